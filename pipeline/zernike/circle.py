"""Circle Zernike polynomials on the unit disk and their Cartesian derivatives.

A mode ``(n, m)`` (see :mod:`wavestack.pipeline.zernike.indices`) is

    Z_n^m(rho, theta) = N_n^m * R_n^|m|(rho) * cos(m theta)     (m >= 0)
    Z_n^m(rho, theta) = N_n^m * R_n^|m|(rho) * sin(|m| theta)   (m < 0)

with ``rho, theta`` the polar coordinates of ``(x, y)`` (x right, y up, theta from +x
counter-clockwise) and ``N`` from :func:`~wavestack.pipeline.zernike.indices.normalisation_factor`.

The radial polynomials come from the three-term recurrence of Shakibaei &
Paramesran [1]_ (their main result),

    R_n^m(r) = r * (R_{n-1}^{|m-1|}(r) + R_{n-1}^{m+1}(r)) - R_{n-2}^m(r),

with ``R_n^n = r^n`` and ``R_n^m = 0`` for ``n < m``.  It needs only additions and
multiplications by ``r``, and stays accurate where the explicit factorial sum (Noll
1976, definition of R_n^m) suffers from cancellation between large alternating terms.  Its
derivative ``R'`` and ``Q = R / r`` (for ``m >= 1``) follow from the same recurrence,
so the Cartesian gradient needs no division by ``r`` and is exact at the origin.

References
----------
.. [1] B. H. Shakibaei, R. Paramesran, "Recursive formula to compute Zernike radial
   polynomials", Opt. Lett. 38, 2487-2489 (2013).
.. [2] R. J. Noll, "Zernike polynomials and atmospheric turbulence",
   J. Opt. Soc. Am. 66, 207-211 (1976).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .modes import validate_mode
from .normalisation import Normalisation, normalisation_factor

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class _RadialParts:
    """Radial functions keyed by ``(n, |m|)``.

    ``values`` holds ``R``; ``slopes`` holds ``dR/drho`` and ``quotients`` holds
    ``R / rho`` (for ``|m| >= 1``), both empty when derivatives were not requested.
    """

    values: dict[tuple[int, int], FloatArray]
    slopes: dict[tuple[int, int], FloatArray] = field(default_factory=dict)
    quotients: dict[tuple[int, int], FloatArray] = field(default_factory=dict)


# --------------------------------------------------------------------------- input checks


def _points(x: ArrayLike, y: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Return ``x, y`` as finite float64 1-D arrays of equal length, or raise ValueError."""
    xs = np.asarray(x, dtype=np.float64)
    ys = np.asarray(y, dtype=np.float64)
    if xs.ndim != 1 or ys.ndim != 1:
        raise ValueError(f"x and y must be 1-D arrays, got shapes {xs.shape} and {ys.shape}")
    if xs.size != ys.size:
        raise ValueError(f"x and y must have the same length, got {xs.size} and {ys.size}")
    if not (np.all(np.isfinite(xs)) and np.all(np.isfinite(ys))):
        raise ValueError("x and y must be finite")
    return xs, ys


def _modes(modes: Iterable[tuple[int, int]]) -> list[tuple[int, int]]:
    """Validate a sequence of ``(n, m)`` pairs."""
    checked: list[tuple[int, int]] = []
    for mode in modes:
        try:
            n, m = mode
        except (TypeError, ValueError):
            raise ValueError(f"each mode must be a pair (n, m), got {mode!r}") from None
        checked.append(validate_mode(n, m))
    return checked


# --------------------------------------------------------------------------- radial recurrence


def _radial_table(
    wanted: set[tuple[int, int]], rho: FloatArray, derivatives: bool
) -> _RadialParts:
    """Evaluate ``R_n^m`` (and optionally ``R'`` and ``Q = R/r``) for every wanted ``(n, m>=0)``.

    One sweep ``n = 0 .. n_max`` of the Shakibaei-Paramesran recurrence, keeping only the
    two previous orders.  ``R_{n-1}^{m+1}`` with ``m + 1 > n - 1`` (zero by definition)
    occurs only on the diagonal ``m = n``, which is computed as ``r * R_{n-1}^{n-1}``.

    Differentiating ``R_n^m = r S - R_{n-2}^m`` with ``S = R_{n-1}^{|m-1|} + R_{n-1}^{m+1}``
    gives ``R'_n^m = S + r S' - R'_{n-2}^m``; dividing it by ``r`` gives
    ``Q_n^m = S - Q_{n-2}^m`` for ``m >= 1``.  On the diagonal ``R_n^n = r^n``,
    ``R'_n^n = n r^(n-1)`` and ``Q_n^n = r^(n-1)``.
    """
    parts = _RadialParts(values={})
    if not wanted:
        return parts
    n_max = max(n for n, _ in wanted)
    # Three rotating buffers per quantity, rows indexed by m.  Order n writes the rows
    # m = n, n-2, ..., and its recurrence reads order n-1 at m -+ 1 and order n-2 at m:
    # rows of exactly the parity those orders wrote.  Rows left over from order n-3 have
    # the other parity and are never read, so no buffer needs clearing between orders.
    shape = (n_max + 1, rho.size)
    d_shape = shape if derivatives else (n_max + 1, 0)  # empty rows when not wanted
    values = [np.zeros(shape) for _ in range(3)]
    slopes = [np.zeros(d_shape) for _ in range(3)]
    quots = [np.zeros(d_shape) for _ in range(3)]

    for n in range(n_max + 1):
        value, value_prev1, value_prev2 = values[n % 3], values[(n - 1) % 3], values[(n - 2) % 3]
        slope, slope_prev1, slope_prev2 = slopes[n % 3], slopes[(n - 1) % 3], slopes[(n - 2) % 3]
        quot, quot_prev2 = quots[n % 3], quots[(n - 2) % 3]
        for m in range(n % 2, n + 1, 2):
            if n == 0:
                value[0] = 1.0  # R_0^0 = 1
                slope[0] = 0.0
            elif m == n:
                below = value_prev1[n - 1]  # r^(n-1)
                np.multiply(rho, below, out=value[m])
                if derivatives:
                    np.multiply(n, below, out=slope[m])
                    quot[m] = below
            else:
                s = value_prev1[abs(m - 1)] + value_prev1[m + 1]
                np.multiply(rho, s, out=value[m])
                value[m] -= value_prev2[m]
                if derivatives:
                    s_slope = slope_prev1[abs(m - 1)] + slope_prev1[m + 1]
                    np.multiply(rho, s_slope, out=slope[m])
                    slope[m] += s
                    slope[m] -= slope_prev2[m]
                    if m >= 1:
                        np.subtract(s, quot_prev2[m], out=quot[m])
            if (n, m) in wanted:
                parts.values[(n, m)] = value[m].copy()
                if derivatives:
                    parts.slopes[(n, m)] = slope[m].copy()
                    if m >= 1:
                        parts.quotients[(n, m)] = quot[m].copy()
    return parts


def zernike_radial(n: int, m: int, rho: ArrayLike) -> FloatArray:
    """Evaluate the Zernike radial polynomial ``R_n^|m|(rho)``.

    Computed by the Shakibaei-Paramesran recurrence, which is accurate to a few units of
    rounding for all ``n`` used in practice (the factorial sum is not).

    Parameters
    ----------
    n : int
        Radial order, ``n >= 0``.
    m : int
        Azimuthal frequency; its sign is ignored (``R`` depends on ``|m|`` only).
    rho : array_like, shape (N,) or scalar
        Normalised radius (dimensionless, 1 at the pupil edge).  Values above 1 are
        evaluated as the polynomial they are.

    Returns
    -------
    numpy.ndarray, same shape as ``rho``
        ``R_n^|m|(rho)``; ``R_n^|m|(1) = 1``.

    Raises
    ------
    ValueError
        If ``(n, m)`` is not a valid mode or ``rho`` is not finite.

    References
    ----------
    Shakibaei & Paramesran (2013), Opt. Lett. 38, 2487, recurrence
    ``R_n^m = r (R_{n-1}^{|m-1|} + R_{n-1}^{m+1}) - R_{n-2}^m``; Noll (1976) for the
    factorial-sum definition it reproduces.
    """
    n, m = validate_mode(n, m)
    radii = np.asarray(rho, dtype=np.float64)
    if not np.all(np.isfinite(radii)):
        raise ValueError("rho must be finite")
    flat = radii.reshape(-1)
    table = _radial_table({(n, abs(m))}, flat, derivatives=False)
    return table.values[(n, abs(m))].reshape(radii.shape)


# --------------------------------------------------------------------------- assembly (shared)


def _angles(x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Return ``rho`` and ``theta`` (from +x, counter-clockwise; 0 at the origin)."""
    return np.hypot(x, y), np.arctan2(y, x)


def _assemble_values(
    modes: Sequence[tuple[int, int]],
    factors: Sequence[float],
    radial: _RadialParts,
    theta: FloatArray,
) -> FloatArray:
    """Combine radial parts and ``cos/sin(m theta)`` into the (N, M) basis matrix.

    Used by the circle and the annular bases alike: both are ``N R(rho) trig(m theta)``.
    The matrix is filled mode by mode into contiguous memory and returned as the
    transposed (column-major) view, which avoids slow strided writes.
    """
    trig = {k: (np.cos(k * theta), np.sin(k * theta)) for k in {abs(m) for _, m in modes}}
    rows = np.empty((len(modes), theta.size))  # one contiguous row per mode
    for row, ((n, m), factor) in enumerate(zip(modes, factors)):
        cos_m, sin_m = trig[abs(m)]
        angular = sin_m if m < 0 else cos_m
        np.multiply(factor * radial.values[(n, abs(m))], angular, out=rows[row])
    return rows.T


def _assemble_gradient(
    modes: Sequence[tuple[int, int]],
    factors: Sequence[float],
    radial: _RadialParts,
    theta: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Cartesian derivatives of ``N R(rho) trig(m theta)`` from ``R'`` and ``Q = R / rho``.

    With ``d rho/dx = cos t``, ``d theta/dx = -sin t / rho`` (and ``sin t``,
    ``cos t / rho`` for y), the cosine term ``Z = N R cos(mt)`` has

        dZ/dx = N [R' cos t cos mt + m Q sin t sin mt]
        dZ/dy = N [R' sin t cos mt - m Q cos t sin mt]

    and the sine term ``Z = N R sin(mt)``

        dZ/dx = N [R' cos t sin mt - m Q sin t cos mt]
        dZ/dy = N [R' sin t sin mt + m Q cos t cos mt].

    At the origin ``theta`` is whatever ``arctan2`` returns; for ``m = 1`` the two
    terms then add up to the correct limit (``cos^2 + sin^2 = 1``), and for every other
    ``m`` both ``R'(0)`` and ``Q(0)`` vanish, so the result is exact there.
    """
    cos_t, sin_t = np.cos(theta), np.sin(theta)
    trig = {k: (np.cos(k * theta), np.sin(k * theta)) for k in {abs(m) for _, m in modes}}
    grad_x = np.empty((len(modes), theta.size))  # one contiguous row per mode
    grad_y = np.empty((len(modes), theta.size))
    for row, ((n, m), factor) in enumerate(zip(modes, factors)):
        k = abs(m)
        slope = factor * radial.slopes[(n, k)]
        if k == 0:
            np.multiply(slope, cos_t, out=grad_x[row])
            np.multiply(slope, sin_t, out=grad_y[row])
            continue
        mq = (factor * k) * radial.quotients[(n, k)]
        cos_m, sin_m = trig[k]
        if m > 0:
            grad_x[row] = slope * cos_t * cos_m + mq * sin_t * sin_m
            grad_y[row] = slope * sin_t * cos_m - mq * cos_t * sin_m
        else:
            grad_x[row] = slope * cos_t * sin_m - mq * sin_t * cos_m
            grad_y[row] = slope * sin_t * sin_m + mq * cos_t * cos_m
    return grad_x.T, grad_y.T


# --------------------------------------------------------------------------- public bases


def zernike_basis(
    modes: Sequence[tuple[int, int]],
    x: ArrayLike,
    y: ArrayLike,
    normalisation: Normalisation = "rms",
) -> FloatArray:
    """Evaluate circle Zernike polynomials at points of the unit disk.

    Each radial polynomial is computed once (one recurrence sweep up to the largest
    ``n``), and ``cos/sin(m theta)`` once per ``|m|``.

    Parameters
    ----------
    modes : sequence of (int, int), length M
        Modes ``(n, m)``; order and repetitions are kept.
    x, y : array_like, shape (N,)
        Cartesian coordinates in units of the disk radius (x right, y up).  Points with
        ``rho > 1`` are evaluated as the polynomials they are.
    normalisation : {"rms", "edge"}, default "rms"
        ``"rms"``: unit RMS over the unit disk (Noll); ``"edge"``: ``N = 1``.

    Returns
    -------
    numpy.ndarray, shape (N, M)
        ``Z[i, k] = Z_{modes[k]}(x[i], y[i])`` (dimensionless).  Column-major
        (Fortran-ordered): each mode's column is contiguous.

    Raises
    ------
    ValueError
        If ``x`` and ``y`` are not finite 1-D arrays of equal length, a mode is invalid,
        or ``normalisation`` is unknown.

    References
    ----------
    Noll (1976), J. Opt. Soc. Am. 66, 207: definition ``Z = N R_n^m(rho) trig(m theta)``
    and the unit-RMS factor; Shakibaei & Paramesran (2013), Opt. Lett. 38, 2487: the
    radial recurrence.
    """
    xs, ys = _points(x, y)
    checked = _modes(modes)
    factors = [normalisation_factor(n, m, normalisation) for n, m in checked]
    rho, theta = _angles(xs, ys)
    radial = _radial_table({(n, abs(m)) for n, m in checked}, rho, derivatives=False)
    return _assemble_values(checked, factors, radial, theta)


def zernike_gradient(
    modes: Sequence[tuple[int, int]],
    x: ArrayLike,
    y: ArrayLike,
    normalisation: Normalisation = "rms",
) -> tuple[FloatArray, FloatArray]:
    """Evaluate the Cartesian gradient of circle Zernike polynomials.

    Parameters
    ----------
    modes : sequence of (int, int), length M
        Modes ``(n, m)``.
    x, y : array_like, shape (N,)
        Cartesian coordinates in units of the disk radius (x right, y up).
    normalisation : {"rms", "edge"}, default "rms"
        As in :func:`zernike_basis`.

    Returns
    -------
    dzdx, dzdy : numpy.ndarray, shape (N, M) each
        ``dZ/dx`` and ``dZ/dy`` in units of 1 / (disk radius).  Exact at the origin
        (no division by ``rho``).  Column-major, like :func:`zernike_basis`.

    Raises
    ------
    ValueError
        As for :func:`zernike_basis`.

    References
    ----------
    Shakibaei & Paramesran (2013), Opt. Lett. 38, 2487: the radial recurrence,
    differentiated term by term; chain rule for polar coordinates (formulas in
    ``_assemble_gradient``).
    """
    xs, ys = _points(x, y)
    checked = _modes(modes)
    factors = [normalisation_factor(n, m, normalisation) for n, m in checked]
    rho, theta = _angles(xs, ys)
    radial = _radial_table({(n, abs(m)) for n, m in checked}, rho, derivatives=True)
    return _assemble_gradient(checked, factors, radial, theta)
