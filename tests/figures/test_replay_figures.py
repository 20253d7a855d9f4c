"""The replay figures show the series they are given: coefficient lines, aperture changes, latency bars, the map."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import Normalize

from figure_pixels import assert_colour, colour, near, pixel, saved
from wavestack.figures import (
    BAR_COLOUR, SIGNED_CMAP, ReplayCollector, ReplaySeries, coefficient_figure, last_map_figure, latency_figure,
    mode_label, write_replay_figures,
)
from wavestack.pipeline import mode_list


def _series(last_map: bool = True) -> ReplaySeries:
    indices = np.arange(2, 42)
    modes = tuple(mode_list("noll", 11))
    table = np.zeros((indices.size, 11))
    table[:, 3] = 0.3 + 0.002 * indices  # defocus drifting
    table[:, 4] = np.where(indices < 20, -0.2, 0.1)  # astigmatism jumping at the aperture change
    table[7] = np.nan  # an invalid result
    rows, cols = np.indices((30, 30))
    inside = np.hypot(rows - 14.5, cols - 14.5) < 14
    waves = np.where(inside, 0.05 * (rows - 14.5) / 14.5 + 0.02 * np.cos(cols / 3.0), np.nan)
    latency = np.random.default_rng(1).gamma(9.0, 2.0, 200)
    return ReplaySeries("run.h5", indices, table, modes, 1, np.array([2, 20]), latency,
                        waves if last_map else None, 41 if last_map else None)


def test_coefficient_figure_draws_each_leading_mode_and_the_aperture_changes(tmp_path) -> None:
    series = _series()
    figure = coefficient_figure(series)
    image = saved(figure, tmp_path / "coefficients.png")
    axes = figure.axes[0]
    lines = axes.get_lines()
    assert [line.get_label() for line in lines[:8]] == [mode_label(j, *series.modes[j - 1]) for j in range(4, 12)]
    for k, mode in ((0, 3), (1, 4)):  # Z4 is the first line (C0), Z5 the second (C1)
        for i in (3, 12, 30):
            assert near(image, axes, series.indices[i], series.coefficients[i, mode], f"C{k}"), (mode, i)
    assert not near(image, axes, series.indices[12], 0.25, "C1")  # no astigmatism line where there is none
    low, high = axes.get_ylim()
    for change in series.aperture_changes:  # a dashed black line: some black pixel along it
        assert any(near(image, axes, change, y, "black", radius=1) for y in np.linspace(low, high, 9)[1:-1]), change
    assert axes.get_xlabel() == "set index" and axes.get_ylabel() == "coefficient, waves"


def test_latency_figure_is_the_histogram_of_the_recorded_latency(tmp_path) -> None:
    series = _series()
    figure = latency_figure(series, bins=20)
    image = saved(figure, tmp_path / "latency.png")
    axes = figure.axes[0]
    counts, edges = np.histogram(series.latency_ms, bins=20)
    for b in np.argsort(counts)[-3:]:  # the three tallest bins, filled up to half their count
        assert_colour(pixel(image, axes, (edges[b] + edges[b + 1]) / 2, counts[b] / 2), BAR_COLOUR, f"bin {b}")
    tallest = int(np.argmax(counts))
    assert_colour(pixel(image, axes, (edges[tallest] + edges[tallest + 1]) / 2, counts[tallest] * 1.03), "white",
                  "above the tallest bin")
    assert "median" in axes.get_title() and axes.get_xlabel().startswith("latency, ms")


def test_last_map_figure_shows_the_last_result(tmp_path) -> None:
    series = _series()
    figure = last_map_figure(series)
    image = saved(figure, tmp_path / "last.png")
    bound = float(np.nanmax(np.abs(series.last_map)))
    for row, col in ((3, 14), (14, 2), (25, 20), (14, 14)):
        assert_colour(pixel(image, figure.axes[0], col, row),
                      colour(SIGNED_CMAP, Normalize(-bound, bound), series.last_map[row, col]), f"({row}, {col})")
    assert "result 41" in figure.axes[0].get_title() and figure.axes[1].get_ylabel() == "wavefront, waves"
    empty = last_map_figure(_series(last_map=False))
    assert "no valid result" in empty.axes[0].get_title()


def test_write_replay_figures_and_an_empty_collector(tmp_path) -> None:
    paths = write_replay_figures(_series(), tmp_path)
    assert [p.name for p in paths] == ["coefficients.png", "latency.png", "last-map.png"]
    assert all(p.read_bytes()[:4] == b"\x89PNG" for p in paths)
    empty = ReplayCollector().series("none.h5", {"latency_ms": np.array([np.nan, 3.0])}, {"ordering": "noll"})
    assert empty.indices.size == 0 and empty.last_map is None and empty.latency_ms.tolist() == [3.0]
    write_replay_figures(empty, tmp_path)  # nothing replayed still draws (titles say so)
