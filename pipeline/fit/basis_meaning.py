"""What a fitter's coefficients mean: the :class:`~wavestack.pipeline.fit.results.FitBasis` of a
build, and each mode's factor from the unit-RMS columns to the output normalisation."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..zernike import normalisation_factor
from .results import FitBasis, Pupil


def fit_basis(
    method: str,
    ordering: str,
    normalisation: str,
    mode_pairs: list[tuple[int, int]],
    pupil: Pupil,
    obscuration: float | None,
) -> tuple[FitBasis, NDArray[np.float64]]:
    """The basis of a build and the factors that scale its unit-RMS columns' coefficients.

    Parameters
    ----------
    method : str
    ordering : {"noll", "ansi", "fringe"}
    normalisation : {"rms", "edge"}
        The normalisation asked for; annular terms are always unit RMS over their annulus (the
        edge normalisation is a circle notion), and ``qr`` reports ``aperture-rms``.
    mode_pairs : list of (n, m)
    pupil : Pupil
    obscuration : float or None
        The obscuration ratio of annular terms (``annulus``, or ``csf-qcm`` on an annulus).

    Returns
    -------
    basis : FitBasis
    scale : ndarray, shape (M,)
        Each mode's factor from unit RMS to the output normalisation.
    """
    output = "rms" if obscuration is not None else normalisation
    scale = np.array([normalisation_factor(n, m, "rms") / normalisation_factor(n, m, output) for n, m in mode_pairs])
    basis = FitBasis(
        method=method,
        ordering=ordering,
        normalisation="aperture-rms" if method == "qr" else output,
        modes=tuple(mode_pairs),
        first_index=0 if ordering == "ansi" else 1,
        pupil=pupil,
        annular_obscuration=obscuration,
    )
    return basis, scale
