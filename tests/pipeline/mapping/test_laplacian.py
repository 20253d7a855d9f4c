"""Tests for the cotangent and graph Laplacians and the factorise-once Dirichlet solver."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.spatial import Delaunay

from wavestack.pipeline.mapping.laplacian import DirichletSolver, cotangent_laplacian, graph_laplacian

ORDERINGS = ("MMD_AT_PLUS_A", "MMD_ATA", "COLAMD", "NATURAL")


def ccw(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Reorder each triangle counter-clockwise."""
    p = vertices[triangles]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    clockwise = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0] < 0
    out = triangles.copy()
    out[clockwise] = out[clockwise][:, [0, 2, 1]]
    return out.astype(np.int64)


def triangle_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    p = vertices[triangles]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    return 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])


def boundary_vertices(triangles: np.ndarray) -> np.ndarray:
    """Vertices on an edge that belongs to exactly one triangle."""
    pairs = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    edges = np.sort(pairs, axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    return np.unique(unique[counts == 1])


def jittered_delaunay(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Delaunay mesh of an (n+1)^2 grid on the unit square, interior points jittered by 0.35 h."""
    rng = np.random.default_rng(seed)
    axis = np.linspace(0, 1, n + 1)
    grid = np.stack(np.meshgrid(axis, axis), -1).reshape(-1, 2)
    inside = np.all((grid > 1e-9) & (grid < 1 - 1e-9), axis=1)
    grid[inside] += rng.uniform(-0.35, 0.35, (inside.sum(), 2)) / n
    return grid, ccw(grid, Delaunay(grid).simplices)


def sheared_grid(
    nx: int, ny: int, seed: int, jitter: float = 0.25
) -> tuple[np.ndarray, np.ndarray]:
    """Unit square split into nx x ny cells, each cut along a random diagonal, interior jittered.

    Random diagonals plus jitter produce non-Delaunay edges (positive off-diagonal cotangent
    entries). Jitter up to 0.25 of a cell per coordinate cannot fold a triangle; checked.
    """
    rng = np.random.default_rng(seed)
    xs, ys = np.linspace(0, 1, nx + 1), np.linspace(0, 1, ny + 1)
    vertices = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    inside = np.all((vertices > 1e-9) & (vertices < 1 - 1e-9), axis=1)
    vertices[inside] += rng.uniform(-jitter, jitter, (inside.sum(), 2)) * [1 / nx, 1 / ny]
    j, i = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    a = (j * (nx + 1) + i).ravel()
    b, c, d = a + 1, a + nx + 2, a + nx + 1
    cut = rng.random(a.size) < 0.5
    first = np.where(cut[:, None], np.column_stack([a, b, c]), np.column_stack([a, b, d]))
    second = np.where(cut[:, None], np.column_stack([a, c, d]), np.column_stack([b, c, d]))
    triangles = np.concatenate([first, second]).astype(np.int64)
    assert triangle_areas(vertices, triangles).min() > 0  # counter-clockwise, no fold
    return vertices, triangles


def p1_energy(vertices: np.ndarray, triangles: np.ndarray, u: np.ndarray) -> float:
    """Independent reference: sum over triangles of area * |grad u|^2 (gradient by 2x2 solve)."""
    p = vertices[triangles]
    edges = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]], axis=1)  # (T, 2, 2) rows = edges
    du = u[triangles[:, 1:]] - u[triangles[:, :1]]  # (T, 2)
    grad = np.linalg.solve(edges, du[:, :, None])[:, :, 0]
    return float(np.sum(triangle_areas(vertices, triangles) * np.sum(grad**2, axis=1)))


MESHES = {
    "delaunay": lambda: jittered_delaunay(24, seed=1),
    "non-delaunay": lambda: sheared_grid(20, 13, seed=2),
}


@pytest.mark.parametrize("mesh", MESHES)
@pytest.mark.parametrize(("a", "b"), [(1.0, 0.0), (0.0, 1.0), (-0.7, 2.3)])
def test_cotangent_energy_of_linear_function_is_exact(mesh: str, a: float, b: float) -> None:
    vertices, triangles = MESHES[mesh]()
    stiffness = cotangent_laplacian(vertices, triangles)
    u = a * vertices[:, 0] + b * vertices[:, 1] + 0.4
    area = triangle_areas(vertices, triangles).sum()
    # Exact identity; a few hundred O(1) terms summed, rounding measured ~1e-15 relative.
    assert u @ stiffness @ u == pytest.approx((a * a + b * b) * area, rel=1e-10)


@pytest.mark.parametrize("mesh", MESHES)
def test_cotangent_energy_matches_p1_integral_for_any_field(mesh: str) -> None:
    vertices, triangles = MESHES[mesh]()
    u = np.random.default_rng(3).normal(size=len(vertices))
    stiffness = cotangent_laplacian(vertices, triangles)
    # Two independent evaluations of the same integral; rounding only (measured 1e-15).
    assert u @ stiffness @ u == pytest.approx(p1_energy(vertices, triangles, u), rel=1e-10)


def test_non_delaunay_mesh_really_has_positive_off_diagonals() -> None:
    # Guard for the test above: the "non-delaunay" mesh must exercise negative cotangent sums.
    vertices, triangles = MESHES["non-delaunay"]()
    off = sp.triu(cotangent_laplacian(vertices, triangles), k=1)
    assert off.max() > 1e-3


def test_cotangent_laplacian_is_symmetric_psd_with_constant_kernel() -> None:
    vertices, triangles = sheared_grid(8, 6, seed=4)
    dense = cotangent_laplacian(vertices, triangles).toarray()
    np.testing.assert_allclose(dense, dense.T, rtol=0, atol=1e-14)
    np.testing.assert_allclose(dense.sum(axis=1), 0, atol=1e-12)
    eigenvalues = np.linalg.eigvalsh(dense)
    scale = eigenvalues[-1]
    # One zero eigenvalue (constants) to rounding, all others clearly positive.
    assert abs(eigenvalues[0]) < 1e-12 * scale
    assert eigenvalues[1] > 1e-4 * scale


def test_cotangent_laplacian_rejects_clockwise_and_degenerate_triangles() -> None:
    vertices = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [2.0, 0.0]])
    with pytest.raises(ValueError, match="clockwise or degenerate"):
        cotangent_laplacian(vertices, np.array([[0, 2, 1]]))
    with pytest.raises(ValueError, match="clockwise or degenerate"):
        cotangent_laplacian(vertices, np.array([[0, 1, 3]]))  # collinear
    with pytest.raises(ValueError, match="out of range"):
        cotangent_laplacian(vertices, np.array([[0, 1, 4]]))


@pytest.mark.parametrize("mesh", MESHES)
def test_harmonic_interpolation_reproduces_linear_functions(mesh: str) -> None:
    # Linear precision: (K x)_i = 0 at every interior vertex of any planar mesh, Delaunay or not.
    vertices, triangles = MESHES[mesh]()
    boundary = boundary_vertices(triangles)
    linear = 0.3 + 1.7 * vertices[:, 0] - 0.9 * vertices[:, 1]
    solver = DirichletSolver(cotangent_laplacian(vertices, triangles), boundary)
    # SPD system with condition ~ n^2 ~ 1e3: measured max error 5e-15.
    np.testing.assert_allclose(solver.solve(linear[boundary]), linear, rtol=0, atol=1e-11)


def test_graph_laplacian_does_not_reproduce_linear_functions() -> None:
    # Counterpart of the test above: Tutte relaxation moves interior vertices to neighbour means,
    # which the jittered vertices are not (measured max error 0.03).
    vertices, triangles = jittered_delaunay(24, seed=1)
    boundary = boundary_vertices(triangles)
    solver = DirichletSolver(graph_laplacian(triangles, len(vertices)), boundary)
    error = np.abs(solver.solve(vertices[boundary, 0]) - vertices[:, 0]).max()
    assert error > 1e-3


def test_discrete_maximum_principle_on_delaunay_mesh() -> None:
    # Delaunay => cot a + cot b >= 0 on interior edges => M-matrix => no new extrema inside.
    vertices, triangles = jittered_delaunay(24, seed=5)
    boundary = boundary_vertices(triangles)
    data = np.random.default_rng(6).uniform(-1, 2, boundary.size)
    u = DirichletSolver(cotangent_laplacian(vertices, triangles), boundary).solve(data)
    assert u.min() >= data.min() - 1e-12
    assert u.max() <= data.max() + 1e-12
    assert np.ptp(u) > 2.0  # the data really spans [-1, 2]


def test_graph_laplacian_structure() -> None:
    vertices, triangles = jittered_delaunay(10, seed=7)
    laplacian = graph_laplacian(triangles, len(vertices))
    dense = laplacian.toarray()
    np.testing.assert_array_equal(dense, dense.T)
    np.testing.assert_array_equal(dense.sum(axis=1), 0)
    pairs = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [0, 2]]])
    edges = np.unique(np.sort(pairs, axis=1), axis=0)
    degree = np.bincount(edges.ravel(), minlength=len(vertices))
    np.testing.assert_array_equal(np.diag(dense), degree)
    assert set(np.unique(dense[~np.eye(len(vertices), dtype=bool)])) <= {-1.0, 0.0}
    # Euler: a triangulated disk has V - E + T = 1.
    assert len(vertices) - len(edges) + len(triangles) == 1


def test_graph_energy_is_not_a_dirichlet_integral() -> None:
    # On a 40 x 10 cell grid of the unit square, x and y have the same Dirichlet integral (1),
    # which the cotangent form reproduces; the graph form sums squared edge differences and
    # sees the anisotropy (measured 0.54 vs 8.4).
    vertices, triangles = sheared_grid(40, 10, seed=8, jitter=0.2)
    cot = cotangent_laplacian(vertices, triangles)
    graph = graph_laplacian(triangles, len(vertices))
    x, y = vertices[:, 0], vertices[:, 1]
    assert x @ cot @ x == pytest.approx(1.0, rel=1e-10)
    assert y @ cot @ y == pytest.approx(1.0, rel=1e-10)
    assert (y @ graph @ y) / (x @ graph @ x) > 5.0


@pytest.mark.parametrize("ordering", ORDERINGS)
@pytest.mark.parametrize("symmetric", [True, False])
def test_solver_multiple_rhs_and_orderings_agree(ordering: str, symmetric: bool) -> None:
    vertices, triangles = MESHES["non-delaunay"]()
    boundary = boundary_vertices(triangles)
    stiffness = cotangent_laplacian(vertices, triangles)
    solver = DirichletSolver(stiffness, boundary, permc_spec=ordering, symmetric=symmetric)
    data = np.random.default_rng(9).normal(size=(boundary.size, 3))
    together = solver.solve(data)
    assert together.shape == (len(vertices), 3)
    for column in range(3):
        single = solver.solve(data[:, column])
        assert single.shape == (len(vertices),)
        np.testing.assert_allclose(together[:, column], single, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(together[boundary], data)
    interior = solver.interior_indices
    # Interior equations hold to rounding: (K u)_I = 0.
    np.testing.assert_allclose((stiffness @ together)[interior], 0, atol=1e-10)
    # Energy of (V, k) values is the sum over the columns.
    total = sum(solver.energy(together[:, c]) for c in range(3))
    assert solver.energy(together) == pytest.approx(total, rel=1e-12)


def test_solver_interior_rhs_recovers_a_manufactured_solution() -> None:
    vertices, triangles = jittered_delaunay(16, seed=10)
    boundary = boundary_vertices(triangles)
    stiffness = cotangent_laplacian(vertices, triangles)
    exact = np.random.default_rng(11).normal(size=(len(vertices), 2))
    solver = DirichletSolver(stiffness, boundary)
    load = (stiffness @ exact)[solver.interior_indices]
    np.testing.assert_allclose(solver.solve(exact[boundary], load), exact, rtol=0, atol=1e-10)
    with pytest.raises(ValueError, match="interior_rhs"):
        solver.solve(exact[boundary], load[:-1])


def test_solver_energy_of_linear_function() -> None:
    vertices, triangles = sheared_grid(12, 9, seed=12)
    solver = DirichletSolver(cotangent_laplacian(vertices, triangles), boundary_vertices(triangles))
    u = 2.0 * vertices[:, 0] - 1.0 * vertices[:, 1]
    assert solver.energy(u) == pytest.approx(5.0, rel=1e-10)  # (a^2 + b^2) * area, area 1
    assert solver.energy(vertices) == pytest.approx(2.0, rel=1e-10)  # x and y: 1 each


def test_solver_validates_inputs() -> None:
    vertices, triangles = jittered_delaunay(6, seed=13)
    stiffness = cotangent_laplacian(vertices, triangles)
    boundary = boundary_vertices(triangles)
    with pytest.raises(ValueError, match="distinct"):
        DirichletSolver(stiffness, np.concatenate([boundary, boundary[:1]]))
    with pytest.raises(ValueError, match="out of range"):
        DirichletSolver(stiffness, [len(vertices)])
    with pytest.raises(ValueError, match="square"):
        DirichletSolver(stiffness[:-1], boundary)
    with pytest.raises(ValueError, match="boundary_values"):
        DirichletSolver(stiffness, boundary).solve(np.zeros(boundary.size + 1))


def test_solver_rejects_interior_component_without_boundary() -> None:
    # A second, separate triangle with no Dirichlet vertex: its block is singular. With these
    # coordinates SuperLU does NOT notice (last pivot ~1e-16 instead of 0), so this checks the
    # structural test in the solver, not SuperLU's exact-zero-pivot error.
    vertices, triangles = jittered_delaunay(4, seed=14)
    n = len(vertices)
    island = np.array([[0.0, 0.0], [1.0, 0.1], [0.3, 0.7]]) + 5.0
    all_vertices = np.concatenate([vertices, island])
    all_triangles = np.concatenate([triangles, [[n, n + 1, n + 2]]])
    with pytest.raises(ValueError, match="singular"):
        DirichletSolver(
            cotangent_laplacian(all_vertices, all_triangles), boundary_vertices(triangles)
        )


def test_solver_with_every_vertex_on_the_boundary() -> None:
    vertices = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    solver = DirichletSolver(cotangent_laplacian(vertices, np.array([[0, 1, 2]])), [2, 0, 1])
    np.testing.assert_array_equal(solver.solve([3.0, 1.0, 2.0]), [1.0, 2.0, 3.0])
