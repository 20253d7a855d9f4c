"""The comparison with a simulator's ground truth, seen from the loop (no simulator type here).

:mod:`wavestack.station.devices` builds a :class:`TruthCheck` only for a simulated camera
(:mod:`wavestack.station.sim_truth`); on real hardware there is none and results carry no truth.
"""

from __future__ import annotations

from typing import Protocol

from wavestack.drivers.frames import Frame
from wavestack.station.results import TruthErrors


class TruthCheck(Protocol):
    """Compares results with the simulator's truth of their frames."""

    def capture(self, frame: Frame) -> object | None:
        """The truth of a frame, taken at once (a simulator keeps only its recent frames' truth)."""

    def compare(self, truth: object | None, outcome: object) -> TruthErrors | None:
        """RMS of the true wavefront and of measured minus true (None when there is nothing to compare)."""
