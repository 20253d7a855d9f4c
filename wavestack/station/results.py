"""The station's result record: everything one refit produced, as a plain value and as JSON."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any


@dataclass(frozen=True)
class Counters:
    """Frames and results so far.

    ``acquired`` counts frames the sources produced (gaps in device frame ids included),
    ``dropped`` frames given up by the rings (a slow stage drops instead of queueing), and
    ``processed`` the results computed, valid or not.
    """

    acquired: int
    processed: int
    dropped: int


@dataclass(frozen=True)
class StationResult:
    """One result of the station.

    Attributes
    ----------
    index : int
        Result number in this run, from 0.
    frame_ids : tuple of int
        Device frame ids of the set (one for the carrier method).
    exposure_time_ns : int
        Host time (``time.time_ns``) of the first frame of the set.
    latency_ms : float
        From the first frame's arrival on the host to this result.
    valid : bool
        False: no coefficients to trust; ``reason`` says why. Invalid results are never forwarded
        to the PLC.
    reason : str or None
    coefficients : tuple of float
        Zernike coefficients of the wavefront, ``units`` (waves), ``ordering`` and
        ``normalisation``, starting at index 1 of the ordering (Noll j = 1 is piston).
    ordering, normalisation, units : str
    residual_rms : float
        RMS of the fit residual, waves (NaN when invalid).
    fitter : str
        Method of the fitter that ran (``csf-qcm``, ``qr``, ...).
    fitter_fallback : bool
        True when a ``qr`` fitter stood in while the configured one was being built.
    fitter_diagnostics : dict
        Condition number (``gram_condition``), map fold-overs (``flips``), largest Beltrami
        coefficient (``max_beltrami``).
    aperture : dict
        ``id`` (counted per run), ``changed`` (this set started it), ``topology``,
        ``components``, ``valid_pixels``.
    unwrap_path : str or None
        "spatial" or "temporal".
    counters : Counters
    timings_ms : dict
        Milliseconds per stage.
    truth_rms, truth_error_rms : float or None
        Simulated devices only: RMS of the simulator's true wavefront (piston, tilt removed as the
        fit removes them) and RMS of the measured minus the true wavefront, both over the fitted
        aperture in the fitted subspace, waves.
    output : dict or None
        What went to the PLC: ``sent`` (bool), ``status`` flags, ``command_id``.
    """

    index: int
    frame_ids: tuple[int, ...]
    exposure_time_ns: int
    latency_ms: float
    valid: bool
    reason: str | None
    coefficients: tuple[float, ...]
    ordering: str
    normalisation: str
    units: str
    residual_rms: float
    fitter: str | None
    fitter_fallback: bool
    fitter_diagnostics: dict[str, float | int | None]
    aperture: dict[str, Any]
    unwrap_path: str | None
    counters: Counters
    timings_ms: dict[str, float] = field(default_factory=dict)
    truth_rms: float | None = None
    truth_error_rms: float | None = None
    output: dict[str, Any] | None = None

    @classmethod
    def invalid(cls, index: int, reason: str, counters: Counters, *, ordering: str, exposure_time_ns: int = 0,
                output: dict[str, Any] | None = None) -> StationResult:
        """A result without a measurement (a lost device, a template row): no frames, no fit."""
        return cls(index=index, frame_ids=(), exposure_time_ns=exposure_time_ns, latency_ms=0.0, valid=False,
                   reason=reason, coefficients=(), ordering=ordering, normalisation="rms", units="waves",
                   residual_rms=float("nan"), fitter=None, fitter_fallback=False, fitter_diagnostics={},
                   aperture={}, unwrap_path=None, counters=counters, output=output)

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict with ``"type": "result"`` first; NaN becomes null."""
        values = asdict(self)
        values["frame_ids"] = list(self.frame_ids)
        values["coefficients"] = list(self.coefficients)
        return {"type": "result", **json_ready(values)}


def json_ready(value: Any) -> Any:
    """Replace NaN and infinities by None, recursively (JSON has no NaN)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: json_ready(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(item) for item in value]
    return value
