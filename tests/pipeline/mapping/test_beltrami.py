"""Tests for the per-triangle Beltrami coefficient and area scale of piecewise-linear maps."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wavestack.pipeline.mapping.beltrami import MapQuality, area_scales, beltrami_coefficients, map_quality


def grid_mesh(
    nx: int, ny: int, x0: float = 0.0, y0: float = 0.0, width: float = 1.0, height: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Rectangle cut into nx x ny cells, alternate diagonals, counter-clockwise triangles."""
    xs, ys = np.linspace(x0, x0 + width, nx + 1), np.linspace(y0, y0 + height, ny + 1)
    vertices = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    j, i = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    a = (j * (nx + 1) + i).ravel()
    b, c, d = a + 1, a + nx + 2, a + nx + 1
    cut = ((i + j) % 2 == 0).ravel()[:, None]
    first = np.where(cut, np.column_stack([a, b, c]), np.column_stack([a, b, d]))
    second = np.where(cut, np.column_stack([a, c, d]), np.column_stack([b, c, d]))
    return vertices, np.concatenate([first, second]).astype(np.int64)


def diamond_fan() -> tuple[np.ndarray, np.ndarray]:
    """Vertex 0 at the origin, vertices 1..4 at (1, 0), (0, 1), (-1, 0), (0, -1); four CCW
    triangles. All coordinates used below are exact binary fractions."""
    vertices = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
    triangles = np.array([[0, 1 + k, 1 + (k + 1) % 4] for k in range(4)], dtype=np.int64)
    return vertices, triangles


def cross(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def affine(vertices: np.ndarray, jacobian: np.ndarray, shift=(0.0, 0.0)) -> np.ndarray:
    return vertices @ np.asarray(jacobian, dtype=float).T + shift


def test_identity_and_similarity_are_conformal_and_uniform() -> None:
    vertices, triangles = grid_mesh(7, 5)
    angle, scale = 0.83, 2.5
    cos, sin = math.cos(angle), math.sin(angle)
    rotation = scale * np.array([[cos, -sin], [sin, cos]])
    for image, factor in [(vertices, 1.0), (affine(vertices, rotation, (3.0, -1.0)), scale**2)]:
        # Rounding only, on O(1) edge vectors: measured <= 1.6e-15.
        np.testing.assert_allclose(beltrami_coefficients(vertices, image, triangles), 0, atol=1e-13)
        np.testing.assert_allclose(area_scales(vertices, image, triangles), factor, rtol=1e-13)
        quality = map_quality(vertices, image, triangles)
        assert quality.flips == 0
        assert quality.max_beltrami < 1e-13 and quality.p95_beltrami < 1e-13
        # Normalised by the total-area ratio: a uniform map reads 1 whatever its scale.
        assert quality.area_scale_p5 == pytest.approx(1.0, rel=1e-13)
        assert quality.area_scale_p95 == pytest.approx(1.0, rel=1e-13)


def test_horizontal_stretch_has_mu_one_third() -> None:
    # f(x, y) = (2x, y): f_z = (2 + 1)/2, f_zbar = (2 - 1)/2, mu = 1/3 exactly.
    vertices, triangles = grid_mesh(4, 3)
    image = affine(vertices, [[2.0, 0.0], [0.0, 1.0]])
    np.testing.assert_allclose(beltrami_coefficients(vertices, image, triangles), 1 / 3, atol=1e-14)
    np.testing.assert_allclose(area_scales(vertices, image, triangles), 2.0, rtol=1e-14)
    quality = map_quality(vertices, image, triangles)
    assert quality.max_beltrami == pytest.approx(1 / 3, rel=1e-13)
    assert quality.flips == 0


@settings(max_examples=200, deadline=None)
@given(
    entries=st.lists(st.floats(min_value=-3, max_value=3), min_size=4, max_size=4),
    seed=st.integers(min_value=0, max_value=2**16),
)
def test_mu_matches_jacobian_formula_and_orientation(entries: list[float], seed: int) -> None:
    (ux, uy), (vx, vy) = jacobian = np.array(entries).reshape(2, 2)
    determinant = ux * vy - uy * vx
    f_z = 0.5 * complex(ux + vy, vx - uy)
    f_zbar = 0.5 * complex(ux - vy, vx + uy)
    if abs(determinant) < 1e-3 or abs(f_z) < 1e-3:
        return  # near-degenerate: covered by the dedicated tests
    rng = np.random.default_rng(seed)
    triangle = rng.normal(size=(3, 2))
    if cross(triangle[1] - triangle[0], triangle[2] - triangle[0]) < 0:
        triangle = triangle[[0, 2, 1]]
    if cross(triangle[1] - triangle[0], triangle[2] - triangle[0]) < 1e-2:
        return  # sliver: Cramer's rule loses digits, not what this test is about
    triangles = np.array([[0, 1, 2]])
    image = affine(triangle, jacobian, rng.normal(size=2))
    mu = beltrami_coefficients(triangle, image, triangles)[0]
    # Conditioning of a 2x2 solve on a non-sliver triangle with |f_z| >= 1e-3: 1e-9 is ample.
    assert mu == pytest.approx(f_zbar / f_z, rel=1e-9, abs=1e-9)
    scale = area_scales(triangle, image, triangles)[0]
    assert scale == pytest.approx(determinant, rel=1e-9, abs=1e-12)
    assert (abs(mu) < 1) == (determinant > 0)
    assert map_quality(triangle, image, triangles).flips == int(determinant < 0)


def test_reflection_is_anti_conformal_and_flips_everything() -> None:
    vertices, triangles = grid_mesh(5, 5)
    exact_mirror = affine(vertices, [[1.0, 0.0], [0.0, -1.0]])
    mu = beltrami_coefficients(vertices, exact_mirror, triangles)
    # f = conj(z): f_z = 0 exactly, so mu = inf by the documented convention.
    assert np.all(np.isinf(mu.real)) and np.all(np.abs(mu) > 1)
    quality = map_quality(vertices, exact_mirror, triangles)
    assert quality.flips == len(triangles)
    assert quality.max_beltrami == math.inf and quality.p95_beltrami == math.inf
    assert quality.area_scale_p5 == pytest.approx(-1.0)
    assert quality.area_scale_p95 == pytest.approx(-1.0)
    # A mirror in a tilted line, scaled and shifted: f_z is zero only up to rounding.
    angle = 0.37
    cos, sin = math.cos(2 * angle), math.sin(2 * angle)
    tilted = affine(vertices, 1.7 * np.array([[cos, sin], [sin, -cos]]), (0.2, 5.0))
    assert np.all(np.abs(beltrami_coefficients(vertices, tilted, triangles)) > 1e6)
    assert map_quality(vertices, tilted, triangles).flips == len(triangles)


def test_folded_vertex_flips_exactly_the_crossed_triangles() -> None:
    vertices, triangles = diamond_fan()
    image = vertices.copy()
    # Beyond the lines x + y = 1 and x - y = 1, the two outer edges at the vertex (1, 0).
    image[0] = [1.25, 0.0]
    quality = map_quality(vertices, image, triangles)
    assert quality.flips == 2
    flipped = np.abs(beltrami_coefficients(vertices, image, triangles)) > 1
    np.testing.assert_array_equal(np.flatnonzero(flipped), [0, 3])  # the triangles at (1, 0)
    assert quality.max_beltrami > 1
    # Onto the midpoint of the edge (1, 0)-(0, 1): that triangle collapses onto a segment
    # (exactly: binary fractions), |mu| = 1 up to rounding, and it counts as flipped.
    image[0] = [0.5, 0.5]
    mu = np.abs(beltrami_coefficients(vertices, image, triangles))
    assert mu[0] == pytest.approx(1.0, abs=1e-12)
    assert np.all(mu[1:] < 1)
    assert map_quality(vertices, image, triangles).flips == 1


def test_collapsed_image_is_reported_not_crashed() -> None:
    vertices, triangles = grid_mesh(3, 3)
    point = np.zeros_like(vertices)
    quality = map_quality(vertices, point, triangles)
    assert quality.flips == len(triangles)
    assert quality.max_beltrami == math.inf
    assert math.isnan(quality.area_scale_p5) and math.isnan(quality.area_scale_p95)


def test_area_scale_percentiles_of_a_known_distribution() -> None:
    # Left half of a 20 x 10 grid stretched by 3 in x, right half kept: 100 triangles with
    # s = 3 and 100 with s = 1 (well, x -> piecewise-linear, continuous at x = 0.5).
    vertices, triangles = grid_mesh(20, 10)
    x = vertices[:, 0]
    image = vertices.copy()
    image[:, 0] = np.where(x <= 0.5, 3 * x, 1.5 + (x - 0.5))
    raw = area_scales(vertices, image, triangles)
    assert sorted(set(np.round(raw, 12))) == [1.0, 3.0]
    quality = map_quality(vertices, image, triangles)
    ratio = 2.0 / 1.0  # total image area / total physical area
    assert quality.area_scale_p5 == pytest.approx(1.0 / ratio, rel=1e-12)
    assert quality.area_scale_p95 == pytest.approx(3.0 / ratio, rel=1e-12)
    assert quality.max_beltrami == pytest.approx(0.5, rel=1e-12)  # (3 - 1) / (3 + 1)
    assert quality.p95_beltrami == pytest.approx(0.5, rel=1e-12)


def test_square_map_is_conformal_in_the_limit() -> None:
    # z -> z^2 on [1, 2] x [-0.5, 0.5] (injective there). The P1 interpolant of a conformal
    # map has |mu| = O(h |f''/f'|): halving h halves max |mu| (measured ratios 0.509, 0.504).
    maxima = []
    for n in (8, 16, 32):
        vertices, triangles = grid_mesh(n, n, x0=1.0, y0=-0.5)
        z = vertices[:, 0] + 1j * vertices[:, 1]
        w = z**2
        image = np.column_stack([w.real, w.imag])
        quality = map_quality(vertices, image, triangles)
        assert quality.flips == 0
        maxima.append(quality.max_beltrami)
        # Area scale -> |f'(z)|^2 = 4 |z|^2 at the centroid, O(h) relative (measured 0.20 / n).
        centroid = z[triangles].mean(axis=1)
        expected = 4 * np.abs(centroid) ** 2
        np.testing.assert_allclose(area_scales(vertices, image, triangles), expected, rtol=0.5 / n)
    assert maxima[0] < 0.1
    assert 0.4 < maxima[1] / maxima[0] < 0.6 and 0.4 < maxima[2] / maxima[1] < 0.6


def test_input_validation() -> None:
    vertices, triangles = grid_mesh(2, 2)
    with pytest.raises(ValueError, match="counter-clockwise"):
        map_quality(vertices, vertices, triangles[:, [0, 2, 1]])
    with pytest.raises(ValueError, match="vertices"):
        beltrami_coefficients(vertices, vertices[:-1], triangles)
    with pytest.raises(ValueError, match="non-finite"):
        area_scales(vertices, np.full_like(vertices, np.nan), triangles)
    with pytest.raises(ValueError, match="no triangles"):
        map_quality(vertices, vertices, np.empty((0, 3), dtype=np.int64))
    assert isinstance(map_quality(vertices, vertices, triangles), MapQuality)
