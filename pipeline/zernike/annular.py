"""Annular Zernike polynomials: orthonormal over the annulus ``eps <= rho <= 1``.

For an obscuration ratio ``eps`` in ``[0, 1)`` the mode ``(n, m)`` is

    Z_n^m(rho, theta; eps) = N_n^m * R_n^|m|(rho; eps) * trig(m theta),

with the circle polynomials' factor ``N = sqrt(2(n+1) / (1 + delta_m0))`` and the same
``(n, m)`` indexing and orderings (:mod:`wavestack.pipeline.zernike.indices`).  The radial
functions obey Mahajan's orthogonality [1]_

    integral_eps^1 R_n^m(rho; eps) R_n'^m(rho; eps) rho drho = (1 - eps^2) / (2(n+1)) delta_nn',

so that the mean of ``Z_i Z_j`` over the annulus is ``delta_ij`` (unit RMS), and the sign
makes ``R_n^m(1; eps) > 0``.  For ``m = 0`` this gives ``R_n^0(1; eps) = 1`` as in
Mahajan's tables; for ``m != 0`` and ``eps > 0`` the edge value is below 1, e.g.
``R_1^1(1; eps) = 1 / sqrt(1 + eps^2)`` [2]_.  At ``eps = 0`` they are the circle
polynomials.

Construction.  Write ``R_n^m(rho; eps) = rho^m p_k(rho^2)`` with ``k = (n - m)/2``.  With
``t = rho^2`` the orthogonality becomes ``integral_{eps^2}^1 t^m p_k p_l dt`` ∝
``delta_kl``: the ``p_k`` are the orthogonal polynomials of the weight ``t^m`` on
``[eps^2, 1]``.  Their three-term recurrence coefficients come from the discretised
Stieltjes procedure [3]_ on a Gauss-Legendre rule that integrates every product needed
exactly, and the polynomials (and their derivatives, by differentiating the recurrence)
are then evaluated by that recurrence -- no Gram-Schmidt on monomials, whose Gram matrix
is badly conditioned.

References
----------
.. [1] V. N. Mahajan, "Zernike annular polynomials for imaging systems with annular
   pupils", J. Opt. Soc. Am. 71, 75-85 (1981).
.. [2] V. N. Mahajan, "Zernike annular polynomials and optical aberrations of systems
   with annular pupils", Appl. Opt. 33, 8125-8127 (1994), table of radial polynomials.
.. [3] W. Gautschi, "On generating orthogonal polynomials", SIAM J. Sci. Stat. Comput.
   3, 289-317 (1982); W. Gautschi, Orthogonal Polynomials: Computation and
   Approximation, Oxford (2004), section 2.2.3.1.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import is_real
from .circle import _angles, _assemble_gradient, _assemble_values, _modes, _points, _RadialParts
from .modes import validate_mode
from .normalisation import normalisation_factor

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class _Recurrence:
    """Orthonormal three-term recurrence ``b_{k+1} p_{k+1} = (t - a_k) p_k - b_k p_{k-1}``.

    ``b[0]`` is ``sqrt(mu_0)``, the square root of the weight's total mass, so that
    ``p_0 = 1 / b[0]``.
    """

    a: FloatArray  # shape (k_max,)
    b: FloatArray  # shape (k_max + 1,)


def _check_obscuration(obscuration: object) -> float:
    """Return the obscuration ratio as a float in ``[0, 1)`` or raise ValueError."""
    if not is_real(obscuration):
        raise ValueError(f"obscuration must be a real number in [0, 1), got {obscuration!r}")
    value = float(obscuration)
    if not (math.isfinite(value) and 0.0 <= value < 1.0):
        raise ValueError(f"obscuration must be in [0, 1) (inner / outer radius), got {value!r}")
    return value


def _stieltjes(m_abs: int, k_max: int, t_min: float) -> _Recurrence:
    """Recurrence coefficients of the polynomials orthonormal for ``t^m_abs`` on ``[t_min, 1]``.

    Discretised Stieltjes procedure (Gautschi 1982): the inner product is replaced by a
    Gauss-Legendre sum, which is exact because every integrand met below is a
    polynomial of degree at most ``2 k_max + m_abs`` and the rule with ``q`` nodes is
    exact up to degree ``2q - 1``.
    """
    nodes = k_max + m_abs // 2 + 2  # 2*nodes - 1 >= 2*k_max + m_abs + 2
    x, w = np.polynomial.legendre.leggauss(nodes)
    half = 0.5 * (1.0 - t_min)
    t = (0.5 * (1.0 + t_min)) + half * x
    weight = half * w * t**m_abs

    a = np.empty(k_max)
    b = np.empty(k_max + 1)
    b[0] = math.sqrt(float(np.sum(weight)))
    p_prev = np.zeros(nodes)
    p = np.full(nodes, 1.0 / b[0])
    for k in range(k_max):
        a[k] = float(np.sum(weight * t * p * p))
        v = (t - a[k]) * p - (b[k] * p_prev if k > 0 else 0.0)
        b[k + 1] = math.sqrt(float(np.sum(weight * v * v)))
        p_prev, p = p, v / b[k + 1]
    return _Recurrence(a=a, b=b)


def _orthonormal_polynomials(
    recurrence: _Recurrence, t: FloatArray, derivatives: bool
) -> tuple[list[FloatArray], list[FloatArray]]:
    """Evaluate ``p_0 .. p_kmax`` at ``t`` (and ``dp/dt`` by the differentiated recurrence).

    ``b_{k+1} p'_{k+1} = p_k + (t - a_k) p'_k - b_k p'_{k-1}``.
    """
    k_max = recurrence.a.size
    values = [np.full(t.shape, 1.0 / recurrence.b[0])]
    slopes = [np.zeros(t.shape)] if derivatives else []
    for k in range(k_max):
        a_k, b_k, b_next = recurrence.a[k], recurrence.b[k], recurrence.b[k + 1]
        value = (t - a_k) * values[k]
        if k > 0:
            value -= b_k * values[k - 1]
        values.append(value / b_next)
        if derivatives:
            slope = values[k] + (t - a_k) * slopes[k]
            if k > 0:
                slope -= b_k * slopes[k - 1]
            slopes.append(slope / b_next)
    return values, slopes


def _annular_radial_table(
    wanted: set[tuple[int, int]], rho: FloatArray, obscuration: float, derivatives: bool
) -> _RadialParts:
    """Evaluate ``R_n^m(rho; eps)`` (and ``R'``, ``R / rho``) for every wanted ``(n, m >= 0)``.

    ``R = s_n rho^m p_k(rho^2)`` with ``s_n = sqrt((1 - eps^2)/(n + 1))``, which turns the
    orthonormality ``integral t^m p_k p_l dt = delta_kl`` into Mahajan's
    ``integral R R' rho drho = (1 - eps^2)/(2(n+1)) delta``.  For ``m >= 1``

        R' = s_n rho^(m-1) (m p_k + 2 t p_k'),    R / rho = s_n rho^(m-1) p_k,

    and for ``m = 0``, ``R' = 2 s_n rho p_k'``: no division by ``rho`` anywhere.
    """
    parts = _RadialParts(values={})
    t = rho * rho
    t_min = obscuration * obscuration
    for m in sorted({m for _, m in wanted}):
        k_max = max((n - m) // 2 for n, mm in wanted if mm == m)
        values, slopes = _orthonormal_polynomials(_stieltjes(m, k_max, t_min), t, derivatives)
        rho_m = rho**m
        rho_m_minus_1 = rho ** (m - 1) if m >= 1 else None
        for n in sorted(n for n, mm in wanted if mm == m):
            k = (n - m) // 2
            scale = math.sqrt((1.0 - t_min) / (n + 1))
            parts.values[(n, m)] = scale * rho_m * values[k]
            if not derivatives:
                continue
            if rho_m_minus_1 is None:
                parts.slopes[(n, m)] = 2.0 * scale * rho * slopes[k]
            else:
                parts.slopes[(n, m)] = scale * rho_m_minus_1 * (m * values[k] + 2.0 * t * slopes[k])
                parts.quotients[(n, m)] = scale * rho_m_minus_1 * values[k]
    return parts


def annular_radial(n: int, m: int, rho: ArrayLike, obscuration: float) -> FloatArray:
    """Evaluate the annular Zernike radial polynomial ``R_n^|m|(rho; eps)``.

    Normalised by Mahajan's orthogonality
    ``integral_eps^1 R_n^m R_n'^m rho drho = (1 - eps^2) / (2(n+1)) delta_nn'`` with
    ``R(1; eps) > 0``.  Then ``R_n^0(1; eps) = 1``; for ``m != 0`` and ``eps > 0`` the
    edge value is below 1 (e.g. ``R_1^1 = rho / sqrt(1 + eps^2)``), so "``R(1) = 1``"
    is not a property of this (unit-RMS) family beyond ``m = 0``.

    Parameters
    ----------
    n : int
        Radial order, ``n >= 0``.
    m : int
        Azimuthal frequency; its sign is ignored.
    rho : array_like, shape (N,) or scalar
        Normalised radius (1 at the outer edge).  Values outside ``[eps, 1]`` are
        evaluated as the polynomial they are.
    obscuration : float
        Ratio ``eps`` of inner to outer radius, ``0 <= eps < 1``.

    Returns
    -------
    numpy.ndarray, same shape as ``rho``
        ``R_n^|m|(rho; eps)`` (dimensionless).

    Raises
    ------
    ValueError
        If ``(n, m)`` is not a valid mode, ``rho`` is not finite, or ``obscuration`` is
        not in ``[0, 1)``.

    References
    ----------
    Mahajan (1981), J. Opt. Soc. Am. 71, 75 (orthogonality and definition); Mahajan
    (1994), Appl. Opt. 33, 8125 (closed forms for low orders).
    """
    n, m = validate_mode(n, m)
    eps = _check_obscuration(obscuration)
    radii = np.asarray(rho, dtype=np.float64)
    if not np.all(np.isfinite(radii)):
        raise ValueError("rho must be finite")
    table = _annular_radial_table({(n, abs(m))}, radii.reshape(-1), eps, derivatives=False)
    return table.values[(n, abs(m))].reshape(radii.shape)


def annular_zernike_basis(
    modes: Sequence[tuple[int, int]],
    x: ArrayLike,
    y: ArrayLike,
    obscuration: float,
) -> FloatArray:
    """Evaluate annular Zernike polynomials, unit RMS over the annulus ``eps <= rho <= 1``.

    Parameters
    ----------
    modes : sequence of (int, int), length M
        Modes ``(n, m)``.
    x, y : array_like, shape (N,)
        Cartesian coordinates in units of the outer radius (x right, y up).  Points
        outside the annulus are evaluated as the polynomials they are.
    obscuration : float
        Ratio ``eps`` of inner to outer radius, ``0 <= eps < 1``.

    Returns
    -------
    numpy.ndarray, shape (N, M)
        ``Z[i, k] = Z_{modes[k]}(x[i], y[i]; eps)``; the mean of ``Z_i Z_j`` over the
        annulus is ``delta_ij``.  Column-major (Fortran-ordered), like
        :func:`~wavestack.pipeline.zernike.circle.zernike_basis`.

    Raises
    ------
    ValueError
        If ``x``, ``y`` are not finite 1-D arrays of equal length, a mode is invalid or
        ``obscuration`` is not in ``[0, 1)``.

    References
    ----------
    Mahajan (1981), J. Opt. Soc. Am. 71, 75; Mahajan (1994), Appl. Opt. 33, 8125.
    """
    eps = _check_obscuration(obscuration)
    xs, ys = _points(x, y)
    checked = _modes(modes)
    factors = [normalisation_factor(n, m, "rms") for n, m in checked]
    rho, theta = _angles(xs, ys)
    radial = _annular_radial_table({(n, abs(m)) for n, m in checked}, rho, eps, False)
    return _assemble_values(checked, factors, radial, theta)


def annular_zernike_gradient(
    modes: Sequence[tuple[int, int]],
    x: ArrayLike,
    y: ArrayLike,
    obscuration: float,
) -> tuple[FloatArray, FloatArray]:
    """Evaluate the Cartesian gradient of the unit-RMS annular Zernike polynomials.

    Parameters
    ----------
    modes : sequence of (int, int), length M
        Modes ``(n, m)``.
    x, y : array_like, shape (N,)
        Cartesian coordinates in units of the outer radius (x right, y up).
    obscuration : float
        Ratio ``eps`` of inner to outer radius, ``0 <= eps < 1``.

    Returns
    -------
    dzdx, dzdy : numpy.ndarray, shape (N, M) each
        ``dZ/dx`` and ``dZ/dy`` in units of 1 / (outer radius); finite and exact at the
        origin (no division by ``rho``).  Column-major, like the basis.

    Raises
    ------
    ValueError
        As for :func:`annular_zernike_basis`.

    References
    ----------
    Mahajan (1981), J. Opt. Soc. Am. 71, 75; the three-term recurrence differentiated
    in ``t`` and the polar chain rule (see ``zernike._assemble_gradient``).
    """
    eps = _check_obscuration(obscuration)
    xs, ys = _points(x, y)
    checked = _modes(modes)
    factors = [normalisation_factor(n, m, "rms") for n, m in checked]
    rho, theta = _angles(xs, ys)
    radial = _annular_radial_table({(n, abs(m)) for n, m in checked}, rho, eps, True)
    return _assemble_gradient(checked, factors, radial, theta)
