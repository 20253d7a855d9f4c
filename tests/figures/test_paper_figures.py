"""The seed paper's figures show the kept views: triangles, curves, bars and matrix cells read back from the PNGs."""

from __future__ import annotations

import matplotlib.image
import numpy as np
import pytest
from matplotlib.colors import LogNorm, Normalize

from figure_pixels import assert_colour, colour, near, pixel, saved
from figure_cases import NAME, small_views
from wavestack.figures import (
    AREA_SCALE_FLOOR, BAR_COLOUR, BELTRAMI_BINS, DPI, GRAM_FLOOR, MAGNITUDE_CMAP, SIGNED_CMAP, beltrami_figure,
    ecdf_figure, error_figure, gram_figure, mesh_figure, write_paper_figures,
)
from wavestack.pipeline.mapping import triangle_areas


@pytest.fixture(scope="module")
def views():
    return small_views()


def _largest(points: np.ndarray, triangles: np.ndarray, count: int = 3) -> np.ndarray:
    """The ``count`` largest triangles (most pixels to sample, least touched by edges)."""
    return np.argsort(triangle_areas(points, triangles))[-count:]


def _centroid(points: np.ndarray, triangle: np.ndarray) -> tuple[float, float]:
    x, y = points[triangle].mean(axis=0)
    return float(x), float(y)


def test_mesh_figure_colours_each_triangle_by_its_area_scale(views, tmp_path) -> None:
    figure = mesh_figure(views)
    image = saved(figure, tmp_path / "meshes.png")
    mapped = [v for v in views if v.mapping is not None]
    logs = [np.log10(np.maximum(v.mapping.area_scale, AREA_SCALE_FLOOR)) for v in mapped]
    bound = max(float(np.max(np.abs(s))) for s in logs)  # one symmetric scale for every panel
    norm = Normalize(-bound, bound)
    for k, (view, values) in enumerate(zip(mapped, logs)):
        physical, canonical = figure.axes[2 * k], figure.axes[2 * k + 1]
        m = view.mapping
        for panel, points in ((physical, m.vertices), (canonical, m.canonical)):
            for t in _largest(points, m.triangles):
                assert_colour(pixel(image, panel, *_centroid(points, m.triangles[t])),
                              colour(SIGNED_CMAP, norm, values[t]), f"{view.label} triangle {t}")
        assert "x, px" == physical.get_xlabel() and physical.get_title()
    assert figure.axes[0].get_title().startswith("conformal")


def test_ecdf_figure_draws_each_maps_area_scale_distribution(views, tmp_path) -> None:
    figure = ecdf_figure(views)
    image = saved(figure, tmp_path / "ecdf.png")
    axes = figure.axes[0]
    mapped = [v for v in views if v.mapping is not None]
    assert axes.get_title().startswith(NAME) and axes.get_xscale() == "log"
    for k, view in enumerate(mapped):
        ordered = np.sort(view.mapping.area_scale)
        for q in (0.3, 0.5, 0.8):  # the curve passes through (s at quantile q, q), in the line's colour
            i = int(q * ordered.size)
            assert near(image, axes, ordered[i], (i + 1) / ordered.size, f"C{k}"), (view.label, q)
    # and nowhere near a point no curve passes through: far right at the bottom
    assert not near(image, axes, max(v.mapping.area_scale.max() for v in mapped) * 0.99, 0.02, "C0")


def test_beltrami_figure_shows_mu_per_triangle_and_its_histogram(views, tmp_path) -> None:
    figure = beltrami_figure(views)
    image = saved(figure, tmp_path / "beltrami.png")
    mapped = [v for v in views if v.mapping is not None]
    for k, view in enumerate(mapped):
        m = view.mapping
        panel, histogram = figure.axes[2 * k], figure.axes[2 * k + 1]
        for t in _largest(m.vertices, m.triangles):
            assert_colour(pixel(image, panel, *_centroid(m.vertices, m.triangles[t])),
                          colour(MAGNITUDE_CMAP, Normalize(0.0, 1.0), m.beltrami[t]), f"{view.label} |mu| {t}")
        counts, _ = np.histogram(np.clip(m.beltrami, 0, 1), bins=BELTRAMI_BINS)
        tallest = int(np.argmax(counts))
        centre = (BELTRAMI_BINS[tallest] + BELTRAMI_BINS[tallest + 1]) / 2
        assert_colour(pixel(image, histogram, centre, counts[tallest] / 2), BAR_COLOUR, f"{view.label} bar")
        empty = int(np.argmin(counts))
        gap = (BELTRAMI_BINS[empty] + BELTRAMI_BINS[empty + 1]) / 2
        if counts[empty] == 0:
            assert_colour(pixel(image, histogram, gap, counts[tallest] / 2), "white", f"{view.label} empty bin")
        assert histogram.get_ylabel() == "triangles"


def test_gram_figure_shows_every_methods_matrix(views, tmp_path) -> None:
    figure = gram_figure(views)
    image = saved(figure, tmp_path / "gram.png")
    top = max(1.0, max(float(np.max(np.abs(v.gram))) for v in views))
    norm = LogNorm(GRAM_FLOOR, top, clip=True)
    for k, view in enumerate(views):
        size = view.gram.shape[0]
        for i, j in ((0, 0), (3, 3), (1, 6), (size - 1, 2), (4, 5)):
            assert_colour(pixel(image, figure.axes[k], j + 1, i + 1),
                          colour(MAGNITUDE_CMAP, norm, max(abs(view.gram[i, j]), GRAM_FLOOR)), f"{view.label} G[{i},{j}]")
        eigenvalues = np.linalg.eigvalsh(view.gram)
        assert f"{eigenvalues[-1] / eigenvalues[0]:.4g}" in figure.axes[k].get_title()


def test_error_figure_shows_the_truth_and_each_error_on_one_scale(views, tmp_path) -> None:
    figure = error_figure(views)
    image = saved(figure, tmp_path / "errors.png")
    truth = views[0].truth.astype(np.float64)
    bound = max(float(np.nanmax(np.abs(v.error))) for v in views)
    rows, cols = np.nonzero(views[0].mask)
    picks = np.random.default_rng(3).choice(rows.size, 6, replace=False)
    for r, c in zip(rows[picks], cols[picks]):
        own = np.nanmax(np.abs(truth))
        assert_colour(pixel(image, figure.axes[0], c, r), colour(SIGNED_CMAP, Normalize(-own, own), truth[r, c]),
                      f"truth ({r}, {c})")
        for k, view in enumerate(views):
            assert_colour(pixel(image, figure.axes[1 + k], c, r),
                          colour(SIGNED_CMAP, Normalize(-bound, bound), float(view.error[r, c])),
                          f"{view.label} error ({r}, {c})")


def test_write_paper_figures_writes_every_figure_at_its_size(views, tmp_path) -> None:
    paths = write_paper_figures(views, tmp_path)
    drawers = {"meshes": mesh_figure, "beltrami": beltrami_figure, "gram": gram_figure, "errors": error_figure}
    expected = {f"{stem}-{NAME}.png": draw(views) for stem, draw in drawers.items()}
    expected["area-scale-ecdf.png"] = ecdf_figure(views)
    assert sorted(p.name for p in paths) == sorted(expected)
    for path in paths:
        width, height = expected[path.name].get_size_inches()
        assert matplotlib.image.imread(path).shape[:2] == (round(height * DPI), round(width * DPI)), path.name


def test_figures_need_a_mapped_method_where_they_show_maps(views) -> None:
    unmapped = [v for v in views if v.mapping is None]
    for draw in (mesh_figure, beltrami_figure, ecdf_figure):
        with pytest.raises(ValueError, match="expected at least one mapped method"):
            draw(unmapped)
