"""The N-position rotation test (Evans & Kestner): the part's and the reference's non-symmetric figure, in the fitted basis.

The part is measured at N rotations ``a_k`` on a mount whose axis is the centre of the basis's unit
disk. A Zernike pair of azimuthal order ``m > 0``, written as ``z = c_cos + i c_sin``, turns with the
figure: turned counter-clockwise by ``a`` the pair becomes ``exp(i m a) z`` (:func:`rotate_coefficients`).
Position ``k`` measures

    z_k = exp(i m a_k) P + R

(P the part's pair in its own frame, R the reference's, fixed in the camera's frame). Per pair the
two unknowns are solved by least squares over the N positions; for equally spaced positions this is
Evans & Kestner's average, ``P = mean_k exp(-i m a_k) z_k`` and ``R = mean_k z_k``. Where
``m`` is a multiple of N (and for ``m = 0``, the rotationally symmetric terms) the two columns are
equal for equal spacing and only ``P + R`` is measured: those terms are reported as ``unresolved``
(their sum), and named by their angular orders.

Working in coefficients, not pixels, is what lets a non-circular aperture take part: a turned map
on a non-circular aperture covers other pixels, its coefficients over the disk do not move. The
basis must be covariant under rotation about the axis: circle Zernike polynomials over a pupil
centred on the axis (any normalisation that treats the ``+m`` and ``-m`` members alike: Noll's,
ANSI's and Fringe's do). A mapped basis (CSF-QCM, conformal) is not covariant and is refused by
the caller.

Uncertainty: the estimates are linear in the measured coefficients, ``x = G c`` with ``c`` the N
position vectors stacked, so their covariance is ``G S G^T`` with ``S`` the block-diagonal of the
positions' covariances (each from the robust average of that position's maps).

References
----------
.. [1] C. J. Evans and R. N. Kestner, "Test optics error removal", Appl. Opt. 35(7), 1015-1021 (1996).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["RotationSolution", "angular_orders", "rotate_coefficients", "solve_rotation_test"]

Modes = Sequence[tuple[int, int]]


def _pairs(modes: Modes) -> tuple[list[tuple[int, int, int]], list[int]]:
    """``(index of +m, index of -m, m)`` for each complete pair, and the indices of ``m = 0`` terms."""
    where = {(int(n), int(m)): j for j, (n, m) in enumerate(modes)}
    pairs, symmetric = [], []
    for (n, m), j in where.items():
        if m == 0:
            symmetric.append(j)
        elif m > 0:
            if (n, -m) not in where:
                raise ValueError(f"modes: (n, m) = ({n}, {m}) has no ({n}, {-m}) partner; a rotation needs both")
            pairs.append((j, where[(n, -m)], m))
        elif (n, -m) not in where:
            raise ValueError(f"modes: (n, m) = ({n}, {m}) has no ({n}, {-m}) partner; a rotation needs both")
    return pairs, symmetric


def rotate_coefficients(modes: Modes, coefficients: NDArray[np.floating], angle_rad: float) -> NDArray[np.float64]:
    """The coefficients of the figure turned counter-clockwise (as displayed) by ``angle_rad`` about the disk's centre.

    Parameters
    ----------
    modes : sequence of (n, m)
        The basis's modes (``FitBasis.modes``), signed ``m`` (``m < 0``: the sine member).
    coefficients : array_like, shape (M,) or (K, M)
    angle_rad : float

    Returns
    -------
    ndarray, the shape of ``coefficients``

    Raises
    ------
    ValueError
        A mode without its ``(n, -m)`` partner, or a length that does not match ``modes``.

    Examples
    --------
    >>> modes = [(0, 0), (1, 1), (1, -1), (2, 0), (2, -2), (2, 2)]
    >>> np.round(rotate_coefficients(modes, [0, 1.0, 0, 0, 0, 1.0], np.pi / 2), 12) + 0.0
    array([ 0.,  0.,  1.,  0.,  0., -1.])
    """
    values = np.array(coefficients, dtype=np.float64)
    if values.shape[-1] != len(modes):
        raise ValueError(f"coefficients: expected {len(modes)} values per vector (one per mode), got {values.shape}")
    pairs, _ = _pairs(modes)
    turned = values.copy()
    for plus, minus, m in pairs:
        cos, sin = np.cos(m * angle_rad), np.sin(m * angle_rad)
        turned[..., plus] = cos * values[..., plus] - sin * values[..., minus]
        turned[..., minus] = sin * values[..., plus] + cos * values[..., minus]
    return turned


def angular_orders(modes: Modes, positions: int) -> tuple[int, ...]:
    """The angular orders ``|m|`` among ``modes`` that N equally spaced positions cannot separate (0 and multiples of N)."""
    return tuple(sorted({abs(int(m)) for _, m in modes if abs(int(m)) % positions == 0}))


@dataclass(frozen=True, eq=False)
class RotationSolution:
    """The N-position test's answer, in the basis of the measurements.

    Attributes
    ----------
    modes : tuple of (n, m)
    positions : int
        N.
    angles_rad : ndarray, shape (N,)
        The rotations measured at (read back from the stage), radians counter-clockwise.
    part, reference : ndarray, shape (M,)
        The part's non-symmetric figure in its own frame (at angle 0), and the reference's, in the
        camera's frame; zero on the unresolved terms.
    unresolved : ndarray, shape (M,)
        ``part + reference`` on the unresolved terms (``m = 0`` and ``m`` a multiple of N), zero elsewhere.
    resolved : ndarray of bool, shape (M,)
        Which terms ``part`` and ``reference`` separate.
    unresolved_orders : tuple of int
        The angular orders ``|m|`` left in ``unresolved`` (0 and the multiples of N present).
    part_covariance, reference_covariance : ndarray, shape (M, M)
        Covariances of ``part`` and ``reference`` from the positions' covariances.
    """

    modes: tuple[tuple[int, int], ...]
    positions: int
    angles_rad: NDArray[np.float64]
    part: NDArray[np.float64]
    reference: NDArray[np.float64]
    unresolved: NDArray[np.float64]
    resolved: NDArray[np.bool_]
    unresolved_orders: tuple[int, ...]
    part_covariance: NDArray[np.float64]
    reference_covariance: NDArray[np.float64]

    @property
    def part_stderr(self) -> NDArray[np.float64]:
        """Standard error of each ``part`` coefficient."""
        return np.sqrt(np.clip(np.diag(self.part_covariance), 0.0, None))

    @property
    def reference_stderr(self) -> NDArray[np.float64]:
        """Standard error of each ``reference`` coefficient."""
        return np.sqrt(np.clip(np.diag(self.reference_covariance), 0.0, None))


def solve_rotation_test(
    modes: Modes,
    coefficients: NDArray[np.floating],
    angles_rad: NDArray[np.floating],
    covariances: NDArray[np.floating] | None = None,
) -> RotationSolution:
    """Separate the part's and the reference's non-symmetric figure from N rotated measurements (module notes).

    Parameters
    ----------
    modes : sequence of (n, m)
        The basis's modes; every ``m != 0`` with its ``-m`` partner.
    coefficients : array_like, shape (N, M)
        The measurement at each position (e.g. a robust average of its maps).
    angles_rad : array_like, shape (N,)
        The part's rotation at each position, radians counter-clockwise as displayed.
    covariances : array_like, shape (N, M, M), optional
        Each position's covariance; without them the covariances of the answer are zero.

    Returns
    -------
    RotationSolution

    Raises
    ------
    ValueError
        Fewer than two positions, shapes that disagree, non-finite values, or a mode without its partner.

    Examples
    --------
    >>> modes = [(0, 0), (1, 1), (1, -1), (2, 0), (2, -2), (2, 2)]
    >>> part, reference = np.array([0, 0.2, -0.1, 0.3, 0.05, 0.1]), np.array([0, 0.0, 0.0, 0.02, -0.03, 0.04])
    >>> angles = np.arange(3) * 2 * np.pi / 3
    >>> seen = np.array([rotate_coefficients(modes, part, a) + reference for a in angles])
    >>> solution = solve_rotation_test(modes, seen, angles)
    >>> np.allclose(solution.part[[1, 2, 4, 5]], part[[1, 2, 4, 5]]), solution.unresolved_orders
    (True, (0,))
    """
    modes = tuple((int(n), int(m)) for n, m in modes)
    values = np.asarray(coefficients, dtype=np.float64)
    angles = np.asarray(angles_rad, dtype=np.float64).reshape(-1)
    count = angles.size
    if values.ndim != 2 or values.shape != (count, len(modes)) or count < 2:
        raise ValueError(f"coefficients: expected shape (N, {len(modes)}) with N = {count} >= 2 angles, "
                         f"got {values.shape}")
    if not (np.all(np.isfinite(values)) and np.all(np.isfinite(angles))):
        raise ValueError("coefficients, angles_rad: expected finite values")
    pairs, symmetric = _pairs(modes)
    size = len(modes)
    resolved = np.zeros(size, dtype=bool)
    # x = G c: rows 0..M-1 the part, M..2M-1 the reference, 2M..3M-1 the unresolved sums
    operator = np.zeros((3 * size, count * size))
    for j in symmetric:
        operator[2 * size + j, j::size] = 1.0 / count
    for plus, minus, m in pairs:
        if m % count == 0:
            for j in (plus, minus):
                operator[2 * size + j, j::size] = 1.0 / count
            continue
        resolved[[plus, minus]] = True
        design = np.column_stack([np.exp(1j * m * angles), np.ones(count)])  # z_k = e^{i m a_k} P + R
        inverse = np.linalg.pinv(design)  # (2, N) complex: P, R from the z_k
        for row, offset in ((0, 0), (1, size)):  # the part's rows, then the reference's
            weights = inverse[row]
            # Re(w z) and Im(w z) with z = c_plus + i c_minus
            operator[offset + plus, plus::size] = weights.real
            operator[offset + plus, minus::size] = -weights.imag
            operator[offset + minus, plus::size] = weights.imag
            operator[offset + minus, minus::size] = weights.real
    estimate = operator @ values.reshape(-1)
    covariance = np.zeros((3 * size, 3 * size))
    if covariances is not None:
        blocks = np.asarray(covariances, dtype=np.float64)
        if blocks.shape != (count, size, size) or not np.all(np.isfinite(blocks)):
            raise ValueError(f"covariances: expected finite values of shape ({count}, {size}, {size}), got {blocks.shape}")
        stacked = np.zeros((count * size, count * size))
        for k in range(count):
            # the stacked vector is position-major: position k's terms at k*M .. k*M + M - 1
            stacked[k * size:(k + 1) * size, k * size:(k + 1) * size] = blocks[k]
        covariance = operator @ stacked @ operator.T
    return RotationSolution(
        modes=modes, positions=count, angles_rad=angles, part=estimate[:size], reference=estimate[size:2 * size],
        unresolved=estimate[2 * size:], resolved=resolved, unresolved_orders=angular_orders(modes, count),
        part_covariance=covariance[:size, :size], reference_covariance=covariance[size:2 * size, size:2 * size],
    )
