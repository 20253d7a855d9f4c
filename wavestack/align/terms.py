"""The Zernike terms of a wavefront on a fixed aperture: one fitter for the model and the measurement.

The sensitivity matrix and the measurement must live in one basis, so both go through one
:class:`TermFitter`, built once on the aperture the measurement uses, with the pipeline's
:func:`~wavestack.pipeline.build_fitter` (the same fitter the station runs). The default method
is ``"csf-qcm"``: Noll's RMS-normalised Zernike polynomials on the CSF-QCM map of the long
rounded rectangle onto the unit disk (the seed paper's Type II aperture), where the circle
polynomials are far from orthogonal. ``"circle"`` and ``"qr"`` are the pipeline's others. The
fit is Noll 1..``max_noll`` with nothing removed beforehand (tilt is an alignment signal here:
image motion); piston (Noll 1) is fitted and dropped, the interferometer has no absolute phase.

The mapped basis does not hold an exact physical tilt or defocus (the map is not affine), so a
map of pure tilt leaves a small residual outside Noll 2..22; model and measurement are projected
by the same linear operator, so the estimate sees the same projection of both.

With ``remove_tilt`` (a real bench, where the reference's tip/tilt setting is not known to the
loop, docs/alignment.md) the least-squares *physical* plane over the aperture is taken out of
every map before the fit, and Noll 2 and 3 are dropped from the terms: a plane is then invisible
exactly (the projection is linear and kills any plane), whatever the mapped basis makes of tilt,
and :meth:`TermFitter.rms` judges the map without it. Removing the plane rather than the mapped
Noll 2, 3 is the numerically sound choice: the CSF-QCM map is not affine, so its "tilt" terms are
not the image motion the reference takes out.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline import Fitter, InvalidFrame, build_fitter

__all__ = ["FIT_METHODS", "TermFitter"]

FloatArray = NDArray[np.float64]

#: Methods of :func:`~wavestack.pipeline.build_fitter` the loop accepts.
FIT_METHODS: tuple[str, ...] = ("csf-qcm", "circle", "qr")


@dataclass(frozen=True, eq=False)
class TermFitter:
    """Noll terms 2..``max_noll`` of maps on one aperture (module notes).

    Parameters
    ----------
    mask : ndarray (H, W) of bool
        The aperture (one connected region without holes for ``csf-qcm``).
    max_noll : int
        Highest Noll index fitted, 4 .. 66.
    method : str
        One of :data:`FIT_METHODS`.
    remove_tilt : bool
        Take the aperture's least-squares plane out of every map and return Noll 4..``max_noll``
        (module notes).

    Raises
    ------
    ValueError
        A mask too small, ``max_noll`` or ``method`` out of range, or an aperture the method
        cannot fit (the pipeline's message).

    Examples
    --------
    >>> mask = np.zeros((40, 100), bool); mask[5:35, 5:95] = True
    >>> fitter = TermFitter(mask, 11, method="circle")
    >>> w = fitter.synthesise(np.eye(10)[2])  # Noll 4 = 1 wave RMS
    >>> bool(np.allclose(fitter.terms(w), np.eye(10)[2]))
    True
    """

    mask: NDArray[np.bool_]
    max_noll: int = 22
    method: str = "csf-qcm"
    remove_tilt: bool = False
    _fitter: Fitter = field(init=False, repr=False)
    _plane: FloatArray = field(init=False, repr=False)  # (N, 3) orthonormal

    def __post_init__(self) -> None:
        mask = np.asarray(self.mask, dtype=bool)
        if not 4 <= self.max_noll <= 66:
            raise ValueError(f"max_noll: expected 4 .. 66, got {self.max_noll}")
        if self.method not in FIT_METHODS:
            raise ValueError(f"method: expected one of {FIT_METHODS}, got {self.method!r}")
        if mask.ndim != 2 or int(mask.sum()) < self.max_noll * 3:
            raise ValueError(f"mask: expected a 2-D aperture of at least {3 * self.max_noll} pixels, "
                             f"got shape {mask.shape} with {int(mask.sum())}")
        try:
            fitter = build_fitter(mask, method=self.method, modes=self.max_noll, ordering="noll", dtype=np.float64)
        except ValueError as error:  # IllConditionedBasis, UnsupportedAperture are ValueErrors
            raise ValueError(f"mask: the {self.method} fitter cannot be built on this aperture: {error}") from None
        object.__setattr__(self, "mask", mask)
        object.__setattr__(self, "_fitter", fitter)
        object.__setattr__(self, "_plane", _plane_basis(mask))

    @property
    def first_noll(self) -> int:
        """The first Noll index returned: 2, or 4 with ``remove_tilt``."""
        return 4 if self.remove_tilt else 2

    @property
    def count(self) -> int:
        """Terms returned (Noll ``first_noll`` .. max_noll)."""
        return self.max_noll - self.first_noll + 1

    def rms(self, waves: NDArray[np.floating]) -> float:
        """RMS on the aperture, waves: piston removed, and the plane too with ``remove_tilt``."""
        values = np.asarray(waves, dtype=np.float64)[self.mask]
        if self.remove_tilt:
            values = values - self._plane @ (self._plane.T @ values)
        return float(np.std(values))

    def terms(self, waves: NDArray[np.floating]) -> FloatArray:
        """Noll ``first_noll``..max_noll coefficients, waves RMS, shape (count,).

        Raises
        ------
        ValueError
            ``waves`` of another shape or not finite on the aperture.
        """
        values = np.asarray(waves, dtype=np.float64)
        if values.shape != self.mask.shape:
            raise ValueError(f"waves: expected shape {self.mask.shape}, got {values.shape}")
        bad = int((~np.isfinite(values[self.mask])).sum())
        if bad:
            raise ValueError(f"waves: {bad} non-finite pixels on the aperture")
        if self.remove_tilt:
            values = values.copy()
            inside = values[self.mask]
            values[self.mask] = inside - self._plane @ (self._plane.T @ inside)
        try:
            result = self._fitter.fit(values)
        except InvalidFrame as error:
            raise ValueError(f"waves: {error}") from None
        return np.asarray(result.coefficients[self.first_noll - 1:], dtype=np.float64)

    def synthesise(self, terms: NDArray[np.floating]) -> FloatArray:
        """The map of Noll ``first_noll``..max_noll ``terms`` on the aperture (NaN outside), shape (H, W)."""
        values = np.asarray(terms, dtype=np.float64)
        if values.shape != (self.count,):
            raise ValueError(f"terms: expected {self.count} values (Noll {self.first_noll}..{self.max_noll}), "
                             f"got {values.shape}")
        out = self._fitter.surface(np.concatenate([np.zeros(self.first_noll - 1), values]))
        return np.where(self.mask, out, np.nan)


def _plane_basis(mask: NDArray[np.bool_]) -> FloatArray:
    """An orthonormal basis (N, 3) of the planes ``a + b x + c y`` on the N mask pixels (row-major order)."""
    rows, cols = np.nonzero(mask)
    basis = np.column_stack([np.ones(rows.size), cols - cols.mean(), rows - rows.mean()])
    q, _ = np.linalg.qr(basis.astype(np.float64))
    return q
