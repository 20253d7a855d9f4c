"""Wavefront from Shack-Hartmann slopes: modal (Zernike) least squares.

Both reconstructors (this one and the zonal one) take slopes ``dW/dx, dW/dy`` (x right, y up) in
*wavefront units per unit of the lenslet coordinates*: with lenslet centres in camera pixels
(``LensletLattice.centres_xy``: the modal reconstructor needs only the centres, so any
lattice works) and slopes in radians from
:func:`~wavestack.pipeline.shack_hartmann.spot_slopes.slopes`, multiply the slopes by the pixel
size in micrometres (:func:`~wavestack.pipeline.shack_hartmann.spot_slopes.convert_slopes` with
``wavefront_unit_um=1, length_unit_um=pixel_um``) and the result comes out in micrometres.
Everything that depends only on the geometry is computed once; a frame costs a matrix-vector
product (modal) or one sparse triangular solve pair (zonal).

Modal. With ``W = sum_k a_k Z_k(u(p))`` the slopes are linear in ``a``:
``s = G a`` with ``G = [dZ/dx; dZ/dy]`` at the valid lenslet centres (2V x M). The
reconstructor is the least-squares pseudo-inverse ``G+``, computed once from a QR
factorisation of the column-equilibrated ``G`` (:class:`ModalReconstructor`). The gradient
of a basis function at a lenslet is evaluated at the lenslet centre, whereas the sensor
measures the mean gradient over the subaperture; the two agree for modes up to second order
(linear gradients) and differ by ``O((pitch / R)^2)`` relative for higher orders.
Piston has no gradient: its coefficient is reported as 0.

Zonal reconstruction (Southwell) is :mod:`wavestack.pipeline.shack_hartmann.zonal`.

References
----------
.. [1] W. H. Southwell, "Wave-front estimation from wave-front slope measurements",
   J. Opt. Soc. Am. 70, 998-1006 (1980).
.. [2] R. Cubalchini, "Modal wave-front estimation from phase derivative measurements",
   J. Opt. Soc. Am. 69, 972-977 (1979).
.. [3] G. H. Golub and C. F. Van Loan, Matrix Computations, 4th ed., Johns Hopkins (2013),
   sec. 5.3 (least squares by QR).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.csgraph
import scipy.sparse.linalg
from numpy.typing import ArrayLike, NDArray

from .._checks import positive_float
from ..mapping import CanonicalMap, clamp_to_domain, hat_gradients, locate_points
from ..zernike import annular_zernike_gradient, validate_mode, zernike_gradient

__all__ = ["ModalReconstructor"]

logger = logging.getLogger(__name__)

GradientFunction = Callable[
    [NDArray[np.float64], NDArray[np.float64]], tuple[NDArray[np.float64], NDArray[np.float64]]
]

_MAX_CONDITION = 1e10  # condition number of the equilibrated slope matrix beyond which we refuse


# --------------------------------------------------------------------------- modal


@dataclass(frozen=True, eq=False)
class ModalReconstructor:
    """Least-squares modal reconstructor: slopes at the valid lenslets to mode coefficients.

    Build with :meth:`for_circle`, :meth:`for_map` or :meth:`from_gradient_function`.

    Attributes
    ----------
    modes : tuple of (int, int), length M
        Modes ``(n, m)`` of the coefficients.
    valid : ndarray of bool, shape (L,)
        Lenslets whose slopes are used.
    gradient : ndarray, shape (2V, M)
        ``[dZ/dx; dZ/dy]`` at the V valid lenslet centres, per unit of the centre
        coordinates (piston's columns are zero).
    matrix : ndarray, shape (M, 2V)
        Reconstructor: ``coefficients = matrix @ [sx[valid]; sy[valid]]`` (piston's row zero).
    condition : float
        2-norm condition number of the column-equilibrated ``gradient`` without piston: the
        factor by which relative slope errors can grow in the coefficients.
    """

    modes: tuple[tuple[int, int], ...]
    valid: NDArray[np.bool_]
    gradient: NDArray[np.float64] = field(repr=False)
    matrix: NDArray[np.float64] = field(repr=False)
    condition: float

    @classmethod
    def from_gradient_function(
        cls,
        centres_xy: ArrayLike,
        gradient: GradientFunction,
        modes: Sequence[tuple[int, int]],
        valid: ArrayLike | None = None,
    ) -> ModalReconstructor:
        """Build from any basis-gradient function.

        Parameters
        ----------
        centres_xy : array_like, shape (L, 2)
            Lenslet centres ``(x, y)`` (x right, y up), any length unit.
        gradient : callable
            ``gradient(x, y) -> (dZ/dx, dZ/dy)``, each of shape (V, M), for the valid
            centres' coordinates of shape (V,), per unit of the centre coordinates.
        modes : sequence of (int, int), length M
            The modes the columns stand for (piston ``(0, 0)`` is reported as 0).
        valid : array_like of bool, shape (L,), optional
            Lenslets to use; all by default.

        Returns
        -------
        ModalReconstructor

        Raises
        ------
        ValueError
            If the centres are not finite (L, 2), ``valid`` is not boolean (L,), a mode is
            invalid, the gradients have the wrong shape or are not finite, there are fewer
            slope equations than observable modes, or the modes cannot be told apart from
            the valid lenslets (condition number above 1e10).

        References
        ----------
        Cubalchini (1979), J. Opt. Soc. Am. 69, 972 (modal least squares); Golub & Van Loan
        (2013), sec. 5.3 (QR least squares).
        """
        centres, mask = _centres_and_valid(centres_xy, valid)
        checked = _checked_modes(modes)
        grad_x, grad_y = gradient(centres[mask, 0], centres[mask, 1])
        shape = (int(mask.sum()), len(checked))
        grad_x = np.asarray(grad_x, dtype=np.float64)
        grad_y = np.asarray(grad_y, dtype=np.float64)
        if grad_x.shape != shape or grad_y.shape != shape:
            raise ValueError(
                f"gradient must return two arrays of shape {shape} (valid lenslets, modes), got "
                f"{grad_x.shape} and {grad_y.shape}"
            )
        stacked = np.vstack([grad_x, grad_y])
        if not np.all(np.isfinite(stacked)):
            raise ValueError("gradient returned non-finite values")
        observable = np.array([n > 0 for n, _ in checked], dtype=bool)
        stacked[:, ~observable] = 0.0
        matrix, condition = _pseudo_inverse(stacked, observable)
        return cls(
            modes=tuple(checked),
            valid=mask,
            gradient=stacked,
            matrix=matrix,
            condition=condition,
        )

    @classmethod
    def for_circle(
        cls,
        centres_xy: ArrayLike,
        pupil_centre: tuple[float, float],
        pupil_radius: float,
        modes: Sequence[tuple[int, int]],
        valid: ArrayLike | None = None,
    ) -> ModalReconstructor:
        """Reconstructor for circle Zernike polynomials (unit RMS) over a circular pupil.

        With ``u = (p - c) / R`` the chain rule gives ``dZ/dx = (1 / R) dZ/du``.

        Parameters
        ----------
        centres_xy : array_like, shape (L, 2)
            Lenslet centres ``(x, y)``, x right, y up (e.g. ``lattice.centres_xy()``, pixels).
        pupil_centre : tuple of float
            ``(x, y)`` of the pupil centre, same coordinates.
        pupil_radius : float
            Pupil radius, same unit, ``> 0``.
        modes : sequence of (int, int)
            E.g. ``mode_list("noll", 15)``.
        valid : array_like of bool, shape (L,), optional

        Returns
        -------
        ModalReconstructor
            Coefficients in the wavefront unit of the slopes (slopes per unit of ``centres_xy``).

        Raises
        ------
        ValueError
            As :meth:`from_gradient_function`, or if the pupil centre or radius is invalid.

        References
        ----------
        Noll (1976), J. Opt. Soc. Am. 66, 207 (basis); Cubalchini (1979) (modal estimation).
        """
        centre = _pair(pupil_centre, "pupil_centre")
        radius = positive_float(pupil_radius, "pupil_radius")

        def gradient(x: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
            """Circle Zernike gradients at physical points, per unit of the coordinates."""
            u, v = (x - centre[0]) / radius, (y - centre[1]) / radius
            outside = int(np.count_nonzero(np.hypot(u, v) > 1.0))
            if outside:
                logger.debug("%d valid lenslet centres lie outside the pupil circle", outside)
            grad_u, grad_v = zernike_gradient(modes, u, v)
            return grad_u / radius, grad_v / radius

        return cls.from_gradient_function(centres_xy, gradient, modes, valid)

    @classmethod
    def for_map(
        cls,
        centres_xy: ArrayLike,
        mapping: CanonicalMap,
        modes: Sequence[tuple[int, int]],
        valid: ArrayLike | None = None,
    ) -> ModalReconstructor:
        """Reconstructor for a mapped basis ``Z(Phi(p))`` on an arbitrary aperture.

        ``Phi`` is the piecewise-linear map of ``mapping`` (mesh in pixels, x = col,
        y = -row). On the triangle holding ``p`` its Jacobian is
        ``J = sum_i w_i (grad lambda_i)^T`` (``w_i`` the canonical images of the corners,
        ``grad lambda_i`` the hat-function gradients), and by the chain rule
        ``grad_p Z(Phi(p)) = J^T (grad_w Z)(Phi(p))``. Circle Zernike polynomials on the disk,
        annular ones (obscuration ``mapping.r_in``) on the annulus. Centres outside the mesh
        use the nearest boundary triangle (extrapolated, then clamped into the domain).

        Parameters
        ----------
        centres_xy : array_like, shape (L, 2)
            Lenslet centres in the mesh's coordinates: pixels, ``(col, -row)``
            (``lattice.centres_xy()``).
        mapping : CanonicalMap
        modes : sequence of (int, int)
        valid : array_like of bool, shape (L,), optional

        Returns
        -------
        ModalReconstructor
            Coefficients in the wavefront unit of the slopes (slopes per pixel).

        Raises
        ------
        ValueError
            As :meth:`from_gradient_function`, or if ``mapping`` is not a CanonicalMap.

        Notes
        -----
        The Jacobian is constant per triangle, so the gradients carry the map's
        discretisation error, ``O(h)`` in the mesh spacing ``h`` where the map bends.
        """
        if not isinstance(mapping, CanonicalMap):
            raise ValueError(f"mapping must be a CanonicalMap, got {type(mapping).__name__}")

        def gradient(x: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
            """Mapped-basis gradients ``J^T grad_w Z`` at physical points, per pixel."""
            location = locate_points(mapping.mesh, x, y)
            if np.any(location.outside):
                logger.debug("%d valid lenslet centres outside the mesh", int(location.outside.sum()))
            canonical = clamp_to_domain(location.weights @ mapping.canonical, mapping.r_in)
            corners = mapping.mesh.triangles[location.triangle]
            hats = hat_gradients(mapping.mesh.vertices, corners)  # (V, 3, 2)
            jacobian = np.einsum("nia,nib->nab", mapping.canonical[corners], hats)  # dw_a/dp_b
            if mapping.r_in is None:
                grad_u, grad_v = zernike_gradient(modes, canonical[:, 0], canonical[:, 1])
            else:
                grad_u, grad_v = annular_zernike_gradient(
                    modes, canonical[:, 0], canonical[:, 1], mapping.r_in
                )
            grad_x = jacobian[:, 0, 0, None] * grad_u + jacobian[:, 1, 0, None] * grad_v
            grad_y = jacobian[:, 0, 1, None] * grad_u + jacobian[:, 1, 1, None] * grad_v
            return grad_x, grad_y

        return cls.from_gradient_function(centres_xy, gradient, modes, valid)

    def reconstruct(self, slopes_x: ArrayLike, slopes_y: ArrayLike) -> NDArray[np.float64]:
        """Mode coefficients from one set of slopes: one matrix-vector product.

        Parameters
        ----------
        slopes_x, slopes_y : array_like, shape (L,)
            ``dW/dx`` and ``dW/dy`` per lenslet in wavefront units per unit of the centre
            coordinates; entries of lenslets outside ``valid`` are ignored (may be NaN).

        Returns
        -------
        ndarray, shape (M,)
            Coefficients in the wavefront unit; 0 for piston.

        Raises
        ------
        ValueError
            If the slopes do not have shape (L,) or are not finite at the valid lenslets.
        """
        count = self.valid.size
        sx = np.asarray(slopes_x, dtype=np.float64)
        sy = np.asarray(slopes_y, dtype=np.float64)
        if sx.shape != (count,) or sy.shape != (count,):
            raise ValueError(
                f"slopes_x and slopes_y must have shape ({count},), got {sx.shape} and {sy.shape}"
            )
        stacked = np.concatenate([sx[self.valid], sy[self.valid]])
        if not np.all(np.isfinite(stacked)):
            raise ValueError("slopes must be finite at every valid lenslet of the reconstructor")
        return self.matrix @ stacked

    def predict(self, coefficients: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Slopes of a wavefront given by its coefficients (the forward model).

        Parameters
        ----------
        coefficients : array_like, shape (M,)

        Returns
        -------
        slopes_x, slopes_y : ndarray, shape (L,)
            Model slopes at the valid lenslets, NaN elsewhere.

        Raises
        ------
        ValueError
            If ``coefficients`` does not have shape (M,).
        """
        values = np.asarray(coefficients, dtype=np.float64)
        if values.shape != (len(self.modes),):
            raise ValueError(f"coefficients must have shape ({len(self.modes)},), got {values.shape}")
        model = self.gradient @ values
        count = int(self.valid.sum())
        slopes_x = np.full(self.valid.size, np.nan)
        slopes_y = np.full(self.valid.size, np.nan)
        slopes_x[self.valid] = model[:count]
        slopes_y[self.valid] = model[count:]
        return slopes_x, slopes_y


def _pseudo_inverse(
    stacked: NDArray[np.float64], observable: NDArray[np.bool_]
) -> tuple[NDArray[np.float64], float]:
    """Least-squares inverse of the observable columns (QR of the equilibrated matrix)."""
    columns = stacked[:, observable]
    if columns.shape[0] < columns.shape[1]:
        raise ValueError(
            f"{columns.shape[0]} slope equations cannot determine {columns.shape[1]} modes; "
            "expected more valid lenslets or fewer modes"
        )
    norms = np.linalg.norm(columns, axis=0)
    if np.any(norms == 0):
        raise ValueError("a mode has zero gradient at every valid lenslet; expected observable modes")
    q, r = np.linalg.qr(columns / norms)
    singular = np.linalg.svd(r, compute_uv=False)
    condition = float(singular[0] / singular[-1]) if singular[-1] > 0 else math.inf
    if not condition < _MAX_CONDITION:
        raise ValueError(
            f"the modes cannot be told apart from the valid lenslets (condition number {condition:.3g}); "
            "expected more valid lenslets or fewer modes"
        )
    inverse = scipy.linalg.solve_triangular(r, q.T) / norms[:, None]
    matrix = np.zeros((observable.size, stacked.shape[0]))
    matrix[observable] = inverse
    return matrix, condition


# --------------------------------------------------------------------------- input checks


def _centres_and_valid(
    centres_xy: ArrayLike, valid: ArrayLike | None
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Validated centres (L, 2) and validity mask (L,) with at least one valid lenslet."""
    centres = np.asarray(centres_xy, dtype=np.float64)
    if centres.ndim != 2 or centres.shape[1] != 2 or centres.shape[0] == 0:
        raise ValueError(f"centres_xy must have shape (L, 2) with L >= 1, got {centres.shape}")
    if not np.all(np.isfinite(centres)):
        raise ValueError("centres_xy must be finite")
    if valid is None:
        mask = np.ones(centres.shape[0], dtype=bool)
    else:
        mask = np.asarray(valid)
        if mask.shape != (centres.shape[0],) or mask.dtype != np.bool_:
            raise ValueError(
                f"valid must be a boolean array of shape ({centres.shape[0]},), got shape "
                f"{mask.shape} and dtype {mask.dtype}"
            )
        mask = mask.copy()
    if not mask.any():
        raise ValueError("valid has no True entry; expected at least one valid lenslet")
    return centres, mask


def _checked_modes(modes: Sequence[tuple[int, int]]) -> list[tuple[int, int]]:
    """Modes as a non-empty list of valid ``(n, m)`` pairs."""
    checked = []
    for mode in modes:
        try:
            n, m = mode
        except (TypeError, ValueError):
            raise ValueError(f"modes must hold pairs (n, m), got {mode!r}") from None
        checked.append(validate_mode(n, m))
    if not checked:
        raise ValueError("modes must not be empty")
    return checked


def _pair(value: object, name: str) -> tuple[float, float]:
    """Two finite floats, or raise ValueError naming ``name``."""
    try:
        a, b = value  # type: ignore[misc]
        result = (float(a), float(b))
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair of numbers (x, y), got {value!r}") from None
    if not all(math.isfinite(v) for v in result):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return result
