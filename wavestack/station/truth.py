"""The comparison with a simulator's ground truth, seen from the loop (no simulator type here).

:mod:`wavestack.station.devices` builds a :class:`TruthCheck` only for a simulated camera
(:mod:`wavestack.station.sim_truth`); on real hardware there is none and results carry no truth.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from wavestack.drivers.frames import Frame
from wavestack.station.results import TruthErrors


class TruthCheck(Protocol):
    """Compares results with the simulator's truth of their frames."""

    def capture(self, frame: Frame) -> object | None:
        """The truth of a frame, taken at once (a simulator keeps only its recent frames' truth)."""

    def compare(self, truth: object | None, outcome: object) -> TruthErrors | None:
        """RMS of the true wavefront and of measured minus true (None when there is nothing to compare)."""


def coefficient_errors(measured: ArrayLike, true: ArrayLike, *, first_term: int = 4) -> tuple[float, float]:
    """RMS wavefront of the true coefficients, and of measured minus true, from Noll ``first_term`` on.

    For the unit-RMS circle Zernike basis over the pupil disk the wavefront RMS over the disk is
    the root of the sum of squared coefficients (the basis is orthonormal), so both figures are
    wavefront RMS over the disk, waves. Piston is not sensed by slopes and tilt is alignment,
    hence ``first_term = 4`` by default. Only the terms both vectors describe are compared (the
    measured subspace; a true vector shorter than the measured one counts as zero beyond its end).

    Parameters
    ----------
    measured : array_like, shape (M,)
        Reconstructed coefficients, Noll from j = 1, waves.
    true : array_like, shape (J,)
        True coefficients in the same basis over the same pupil, waves.
    first_term : int
        First Noll index compared.

    Returns
    -------
    truth_rms, error_rms : float
        Waves.
    """
    found = np.asarray(measured, dtype=np.float64)
    reference = np.zeros(found.size)
    given = np.asarray(true, dtype=np.float64)[: found.size]
    reference[: given.size] = given
    start = first_term - 1
    return (float(np.sqrt(np.sum(reference[start:] ** 2))),
            float(np.sqrt(np.sum((found[start:] - reference[start:]) ** 2))))
