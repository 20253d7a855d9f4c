"""Motion of the simulated platform in simulated time: a pure model computed from the clock.

A ``MOV`` re-plans one straight segment in axis space from the present positions to the new
targets, every axis arriving together (a hexapod moves on a straight line in its 6-D coordinates;
PI's controllers call it vector motion). The segment lasts ``max |delta_i| / velocity`` times the
slow-move fault factor; an axis stuck by the fault stays at its start position for the whole
segment, so it never reaches its target. No thread runs: positions are evaluated at the clock's
present time whenever somebody asks. The velocity profile is flat (no acceleration ramps): a
simplification, the simulator only promises where the platform is heading and when it arrives.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Segment", "hold", "plan_segment"]


@dataclass(frozen=True)
class Segment:
    """One straight move: positions go from ``start`` to ``target`` between ``t0`` and ``t0 + duration_s``.

    Axes in ``stuck`` (indices) stay at ``start``. Times are the clock's seconds.

    Examples
    --------
    >>> segment = plan_segment((0.0, 0.0), (2.0, 1.0), now=10.0, velocity=1.0)
    >>> segment.position(11.0), segment.position(12.0), segment.moving(12.0)
    ((1.0, 0.5), (2.0, 1.0), (False, False))
    """

    start: tuple[float, ...]
    target: tuple[float, ...]
    t0: float
    duration_s: float
    stuck: frozenset[int] = frozenset()

    def fraction(self, now: float) -> float:
        """How much of the segment is done at ``now``, 0..1."""
        if self.duration_s <= 0.0:
            return 1.0
        return min(1.0, max(0.0, (now - self.t0) / self.duration_s))

    def position(self, now: float) -> tuple[float, ...]:
        """Every axis's position at ``now`` (exactly ``target`` once the segment is done, stuck axes excepted)."""
        f = self.fraction(now)
        return tuple(s if i in self.stuck else (t if f >= 1.0 else s + (t - s) * f)
                     for i, (s, t) in enumerate(zip(self.start, self.target)))

    def moving(self, now: float) -> tuple[bool, ...]:
        """Per axis: not yet at its target (a stuck axis with somewhere to go moves for ever)."""
        return tuple(p != t for p, t in zip(self.position(now), self.target))


def hold(position: tuple[float, ...], now: float) -> Segment:
    """A segment that stays at ``position`` (after a stop, at power-on)."""
    return Segment(tuple(position), tuple(position), now, 0.0)


def plan_segment(current: tuple[float, ...], target: tuple[float, ...], *, now: float, velocity: float,
                 slow_factor: float = 1.0, stuck: frozenset[int] = frozenset()) -> Segment:
    """The segment from ``current`` to ``target`` at ``velocity`` (units/s), slowed by ``slow_factor`` >= 1."""
    if velocity <= 0.0 or slow_factor <= 0.0:
        raise ValueError(f"velocity and slow_factor must be > 0, got {velocity}, {slow_factor}")
    distance = max((abs(t - c) for c, t in zip(current, target)), default=0.0)
    return Segment(tuple(current), tuple(target), now, distance / velocity * slow_factor, frozenset(stuck))
