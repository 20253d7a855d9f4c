"""Separable Legendre moments: the algebra behind a refit that reads only the frame.

Every circle or annular Zernike term of degree <= D (and the piston/tilt/power terms) is a
polynomial of total degree <= D in the pixel coordinates, hence a fixed combination of products
``P_b(v) P_a(u)`` (``a + b <= D``) of Legendre polynomials in the row coordinate ``v`` and the
column coordinate ``u`` of a box, both scaled to [-1, 1]. For a column ``h`` with coefficients
``t`` in that product basis, ``h^T w = t . vec(P_v^T W P_u)``: the moments ``P_v^T W P_u`` of the
frame (zero outside the fitted pixels) are two thin matrix products, and no M x N operator is
needed (Teague 1980 and Mukundan & Ramakrishnan 1998 compute Zernike moments through geometric
or Legendre moments in the same way).

Conditioning, and why the aperture is cut into strips. On one box around a disk the corners lie
at rho = sqrt(2), where a unit-RMS Zernike term of degree 20 reaches ~5e7: its Legendre
coefficients are that large and cancel, so rounding in the moments is amplified ~5e7 times. The
fitted pixels are therefore split into S horizontal strips, each with its own box (the strip's
rows by the columns its fitted pixels span), whose corners lie within a strip height of a fitted
pixel: measured on a disk at degree 20, the largest absolute row sum of the coefficients
(:func:`amplification`) is 4.9e7 for one box, 2.4e5 for 8 strips, 1.1e4 for 16 and 920 for 32;
at degree 7 it is 384 on one box. Turning the orthonormal coefficients into those of an
ill-conditioned basis multiplies errors by a further sqrt(kappa(G)). The build doubles S until
that product is at most ``MAX_AMPLIFICATION`` (3e4: 16 strips on a disk at degree 20, one box at
degree 7); where no strip count reaches it (kappa(G) above ~1e8) the operator path is used.

Precision. Frames are moved to float64 before any product and the moments accumulate in float64
(BLAS dgemm): float32 accumulation loses ~1e-7 of each moment, which the amplification above
turns into ~1e-3 at degree 20. In float64 each moment carries ~1e-16 relative to the sum of
|w| over the strip, so the coefficients agree with an explicit operator to about
``30 * 1.1e-16 * amplification`` (norm-wise, measured): 1e-10 at ``MAX_AMPLIFICATION``; the
property tests (``tests/pipeline/fit/test_moments.py``) hold it to 1e-9 against the float64
operator path over random apertures, pupils and orderings up to degree 20.

The Gram matrix of the fitted pixels comes from moments of the mask: the products
``P_b P_b'`` are linearised exactly into Legendre polynomials of degree <= 2D (Adams 1878;
the coefficients are non-negative and sum to 1, so no cancellation), so one (2D+1) x (2D+1)
moment matrix of each strip's mask gives the Gram of all product pairs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.polynomial import legendre
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
ColumnFunction = Callable[[FloatArray, FloatArray], FloatArray]  # (x, y) of shape (Q,) -> (Q, K)

# Largest effective amplification (coefficient row sum times sqrt(kappa(G)) of the basis, see the
# module docstring) the moment path accepts. Measured, the coefficients then differ from the
# float64 operator path's by about 30 * 1.1e-16 * amplification: 1e-10 at this limit, a decade
# below the 1e-9 agreement promised. Each doubling of the strips adds a coefficient block read
# per frame (K x (D+1)(D+2)/2 float64: 0.43 MB at 231 modes), so the limit is not set lower.
MAX_AMPLIFICATION = 3e4


@dataclass(frozen=True)
class Strip:
    """A box of fitted pixels: rows ``[row0, row1)`` by columns ``[col0, col1)``."""

    row0: int
    row1: int
    col0: int
    col1: int


def scaled_coordinates(start: int, stop: int) -> tuple[float, float]:
    """Centre and half-width (pixels) that map pixel centres ``start .. stop - 1`` onto [-1, 1]."""
    return (start + stop - 1) / 2.0, max((stop - 1 - start) / 2.0, 0.5)


def legendre_table(start: int, stop: int, degree: int) -> FloatArray:
    """``P_0 .. P_degree`` at the pixel centres ``start .. stop - 1`` scaled to [-1, 1].

    Returns
    -------
    ndarray, shape (stop - start, degree + 1)
        Values bounded by 1 in magnitude.
    """
    mid, half = scaled_coordinates(start, stop)
    return legendre.legvander((np.arange(start, stop) - mid) / half, degree)


def triangle_index(degree: int) -> NDArray[np.intp]:
    """Flat indices ``b * (D + 1) + a`` of the products with ``a + b <= D`` (length (D+1)(D+2)/2)."""
    return np.array([b * (degree + 1) + a for b in range(degree + 1) for a in range(degree + 1 - b)],
                    dtype=np.intp)


def strips_of(mask: NDArray[np.bool_], count: int) -> list[Strip]:
    """Split the rows that hold fitted pixels into at most ``count`` strips of equal height.

    Strips without a fitted pixel are dropped; each box spans the columns of its own pixels.
    """
    rows = np.flatnonzero(mask.any(axis=1))
    first, last = int(rows[0]), int(rows[-1]) + 1
    edges = np.unique(np.linspace(first, last, min(count, last - first) + 1).round().astype(int))
    strips = []
    for start, stop in zip(edges[:-1], edges[1:]):
        cols = np.flatnonzero(mask[start:stop].any(axis=0))
        if cols.size:
            strips.append(Strip(int(start), int(stop), int(cols[0]), int(cols[-1]) + 1))
    return strips


def column_coefficients(
    columns: ColumnFunction, strips: list[Strip], pixel_to_unit: Callable, degree: int
) -> list[FloatArray]:
    """Coefficients of polynomial columns in each strip's products ``P_b(v) P_a(u)``, a + b <= D.

    Gauss-Legendre quadrature with D + 1 nodes per axis is exact for the projection of a
    polynomial of degree <= D in each variable, so the coefficients are exact up to rounding.
    The columns are evaluated once, at the nodes of every strip together.

    Parameters
    ----------
    columns : callable
        ``columns(x, y)`` gives the column values, shape (Q, K), at unit-disk points.
    strips : list of Strip
    pixel_to_unit : callable
        ``pixel_to_unit(rows, cols)`` gives (x, y) of pixel positions (floats).
    degree : int
        D, at least the columns' total degree.

    Returns
    -------
    list of ndarray, shape (K, (D+1)(D+2)/2) each
        One per strip, in the order of :func:`triangle_index`.
    """
    nodes, weights = legendre.leggauss(degree + 1)
    grid_rows, grid_cols = [], []
    for strip in strips:
        row_mid, row_half = scaled_coordinates(strip.row0, strip.row1)
        col_mid, col_half = scaled_coordinates(strip.col0, strip.col1)
        node_rows, node_cols = np.meshgrid(row_mid + row_half * nodes, col_mid + col_half * nodes, indexing="ij")
        grid_rows.append(node_rows.ravel())
        grid_cols.append(node_cols.ravel())
    x, y = pixel_to_unit(np.concatenate(grid_rows), np.concatenate(grid_cols))
    values = np.asarray(columns(x, y))  # (S * Q, K), each strip's Q ordered [row node, column node]
    projector = legendre.legvander(nodes, degree) * weights[:, None] * ((2 * np.arange(degree + 1) + 1) / 2.0)
    grid = values.T.reshape(values.shape[1], len(strips), degree + 1, degree + 1)
    full = projector.T @ grid.transpose(1, 0, 2, 3) @ projector  # (S, K, b, a)
    flat = full.reshape(len(strips), values.shape[1], -1)[:, :, triangle_index(degree)]
    return [np.ascontiguousarray(block) for block in flat]


def amplification(coefficients: FloatArray) -> float:
    """Largest absolute row sum: the factor by which rounding in the moments reaches a column."""
    return float(np.abs(coefficients).sum(axis=1).max())


def _linearisation(degree: int) -> FloatArray:
    """``lam[a, a', c]`` with ``P_a P_a' = sum_c lam[a, a', c] P_c`` (c <= 2D), by exact quadrature."""
    nodes, weights = legendre.leggauss(2 * degree + 1)  # exact to degree 4D + 1 >= 3D
    low = legendre.legvander(nodes, degree)
    high = legendre.legvander(nodes, 2 * degree) * weights[:, None] * ((2 * np.arange(2 * degree + 1) + 1) / 2.0)
    pairs = (low[:, :, None] * low[:, None, :]).reshape(nodes.size, -1)
    return (pairs.T @ high).reshape(degree + 1, degree + 1, 2 * degree + 1)


@dataclass(frozen=True)
class MaskMoments:
    """What the build needs from one strip's fitted pixels.

    Attributes
    ----------
    gram : ndarray, shape (L, L)
        ``sum P_b P_a P_b' P_a'`` over the pixels, products in :func:`triangle_index` order.
    sums : ndarray, shape (L,)
        ``sum P_b P_a`` over the pixels.
    count : int
        Pixels.
    """

    gram: FloatArray
    sums: FloatArray
    count: int


def mask_moments(mask: NDArray[np.bool_], strip: Strip, degree: int,
                 lam: FloatArray | None = None) -> MaskMoments:
    """Gram of the Legendre products over the strip's pixels of ``mask``, from its moments.

    The (2D+1) x (2D+1) moments ``mu[d, c] = sum P_d(v) P_c(u)`` of the mask, then
    ``G[(b, a), (b', a')] = sum lam[b, b', d] lam[a, a', c] mu[d, c]``.
    """
    lam = _linearisation(degree) if lam is None else lam
    box = mask[strip.row0:strip.row1, strip.col0:strip.col1].astype(np.float64)
    rows = legendre_table(strip.row0, strip.row1, 2 * degree)
    cols = legendre_table(strip.col0, strip.col1, 2 * degree)
    mu = (rows.T @ box) @ cols
    flat_lam = lam.reshape(-1, lam.shape[2])  # rows (b, B)
    size = (degree + 1) ** 2
    full = (flat_lam @ mu @ flat_lam.T).reshape((degree + 1,) * 4).transpose(0, 2, 1, 3)  # [b, a, B, A]
    index = triangle_index(degree)
    gram = full.reshape(size, size)[np.ix_(index, index)]
    sums = mu[: degree + 1, : degree + 1].reshape(-1)[index]
    return MaskMoments(gram, sums, int(np.count_nonzero(box)))


def strip_moments(mask: NDArray[np.bool_], strips: list[Strip], degree: int) -> list[MaskMoments]:
    """:func:`mask_moments` of every strip (one linearisation table shared)."""
    lam = _linearisation(degree)
    return [mask_moments(mask, strip, degree, lam) for strip in strips]


def gram_of(coefficients: list[FloatArray], moments: list[MaskMoments]) -> tuple[FloatArray, FloatArray]:
    """``A^T A`` and ``A^T 1`` over the pixels of columns given per strip by their coefficients.

    Parameters
    ----------
    coefficients : list of ndarray, shape (K, L) each
    moments : list of MaskMoments, one per strip

    Returns
    -------
    gram : ndarray, shape (K, K)
    sums : ndarray, shape (K,)
    """
    gram = sum(t @ m.gram @ t.T for t, m in zip(coefficients, moments))
    sums = sum(t @ m.sums for t, m in zip(coefficients, moments))
    gram = 0.5 * (gram + gram.T)
    return np.asarray(gram), np.asarray(sums)
