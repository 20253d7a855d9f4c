"""The Zernike terms of a wavefront on a fixed aperture: one fitter for the model and the measurement.

The sensitivity matrix and the measurement must live in one basis, so both go through one
:class:`TermFitter`, built once on the aperture the measurement uses. The basis is Noll's
RMS-normalised Zernike polynomials (:func:`wavestack.pipeline.zernike.zernike_basis`) on the unit
circle through the pupil's corners (radius half the diagonal of the camera-grid bounding box of
the mask), least-squares fitted by a pseudo-inverse computed once. Piston (Noll 1) is fitted and
dropped: the interferometer has no absolute phase. On the long rounded rectangle the circular
Zernikes are not orthogonal, which a least-squares fit tolerates as long as the Gram matrix is
well conditioned (checked at construction; the CSF-QCM fit of the station is not used here yet:
see docs/alignment.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline.zernike import noll_to_nm, zernike_basis

__all__ = ["TermFitter"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class TermFitter:
    """Least-squares Noll terms 2..``max_noll`` of maps on one aperture.

    Parameters
    ----------
    mask : ndarray (H, W) of bool
        The aperture (at least ``max_noll`` pixels).
    max_noll : int
        Highest Noll index fitted (>= 4).

    Examples
    --------
    >>> mask = np.ones((16, 48), bool)
    >>> fitter = TermFitter(mask, 11)
    >>> w = fitter.synthesise(np.eye(10)[2])  # Noll 4 = 1 wave RMS
    >>> bool(np.allclose(fitter.terms(w), np.eye(10)[2]))
    True
    """

    mask: NDArray[np.bool_]
    max_noll: int = 22
    _basis: FloatArray = field(init=False, repr=False)
    _pinv: FloatArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        mask = np.asarray(self.mask, dtype=bool)
        if mask.ndim != 2 or int(mask.sum()) < max(self.max_noll, 4) * 3:
            raise ValueError(f"mask: expected a 2-D aperture of at least {3 * max(self.max_noll, 4)} pixels, "
                             f"got shape {mask.shape} with {int(mask.sum())}")
        if not 4 <= self.max_noll <= 66:
            raise ValueError(f"max_noll: expected 4 .. 66, got {self.max_noll}")
        rows, cols = np.nonzero(mask)
        cy, cx = (rows.min() + rows.max()) / 2, (cols.min() + cols.max()) / 2
        radius = float(np.hypot(rows.max() - rows.min() + 1, cols.max() - cols.min() + 1) / 2)
        x, y = (cols - cx) / radius, (cy - rows) / radius  # x right, y up
        basis = zernike_basis([noll_to_nm(j) for j in range(1, self.max_noll + 1)], x, y)
        condition = np.linalg.cond(basis)
        if not condition < 1e4:
            raise ValueError(f"mask: the Zernike basis is ill conditioned on this aperture (cond {condition:.3g})")
        object.__setattr__(self, "mask", mask)
        object.__setattr__(self, "_basis", basis)
        object.__setattr__(self, "_pinv", np.linalg.pinv(basis))

    @property
    def count(self) -> int:
        """Terms returned (Noll 2 .. max_noll)."""
        return self.max_noll - 1

    def terms(self, waves: NDArray[np.floating]) -> FloatArray:
        """Noll 2..max_noll coefficients, waves RMS, shape (count,).

        Raises
        ------
        ValueError
            ``waves`` of another shape or not finite on the aperture.
        """
        values = np.asarray(waves, dtype=np.float64)
        if values.shape != self.mask.shape:
            raise ValueError(f"waves: expected shape {self.mask.shape}, got {values.shape}")
        on = values[self.mask]
        if not np.all(np.isfinite(on)):
            raise ValueError(f"waves: {int((~np.isfinite(on)).sum())} non-finite pixels on the aperture")
        return (self._pinv @ on)[1:]

    def synthesise(self, terms: NDArray[np.floating]) -> FloatArray:
        """The map of Noll 2..max_noll ``terms`` on the aperture (NaN outside), shape (H, W)."""
        out = np.full(self.mask.shape, np.nan)
        out[self.mask] = self._basis[:, 1:] @ np.asarray(terms, dtype=np.float64)
        return out
