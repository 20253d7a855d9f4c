"""What the polishing machine can execute: feed, acceleration, travel and dwell limits."""

from __future__ import annotations

from dataclasses import dataclass

from .._checks import finite_float, positive_float


@dataclass(frozen=True)
class MachineLimits:
    """The limits a machine program is planned to and checked against.

    Attributes
    ----------
    max_feed_mm_s : float
        Highest path speed, mm/s; > 0. Sets the shortest dwell a point can have:
        ``step_mm / max_feed_mm_s`` s.
    max_accel_mm_s2 : float
        Highest change of path speed, mm/s^2; > 0.
    travel_x_mm, travel_y_mm : tuple of float
        (lo, hi) of the reachable machine coordinates, mm, lo < hi (the machine frame of
        :class:`~wavestack.pipeline.polishing.grid.GridFrame`).
    max_dwell_per_point_s : float
        Longest dwell at one point, s; > 0.
    max_total_dwell_s : float
        Longest program (sum of all dwells), s; > 0.

    Examples
    --------
    >>> limits = MachineLimits(250.0, 2000.0, (-60.0, 60.0), (-60.0, 60.0), 5.0, 3600.0)
    >>> limits.max_feed_mm_s
    250.0
    """

    max_feed_mm_s: float
    max_accel_mm_s2: float
    travel_x_mm: tuple[float, float]
    travel_y_mm: tuple[float, float]
    max_dwell_per_point_s: float
    max_total_dwell_s: float

    def __post_init__(self) -> None:
        for name in ("max_feed_mm_s", "max_accel_mm_s2", "max_dwell_per_point_s", "max_total_dwell_s"):
            object.__setattr__(self, name, positive_float(getattr(self, name), name))
        for name in ("travel_x_mm", "travel_y_mm"):
            object.__setattr__(self, name, _travel(getattr(self, name), name))


def _travel(value: object, name: str) -> tuple[float, float]:
    try:
        lo, hi = value  # type: ignore[misc]
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (lo, hi) in mm, got {value!r}") from None
    lo_mm, hi_mm = finite_float(lo, f"{name}[0]"), finite_float(hi, f"{name}[1]")
    if not lo_mm < hi_mm:
        raise ValueError(f"{name} must have lo < hi, got {value!r}")
    return (lo_mm, hi_mm)
