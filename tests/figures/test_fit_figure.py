"""The fit figure shows the maps and coefficients it is given (read back pixel by pixel)."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import Normalize

from figure_pixels import assert_colour, colour, pixel, saved
from wavestack.figures import BAR_COLOUR, FitView, SIGNED_CMAP, fit_figure, mode_label, write_fit_figure

SIZE = 24


def _view() -> FitView:
    rows, cols = np.indices((SIZE, SIZE))
    inside = np.hypot(rows - 11.5, cols - 11.5) < 11
    fitted = np.where(inside, 0.2 * (cols - 11.5) / 11.5 - 0.1 * (rows - 11.5) / 11.5, np.nan)
    residual = np.where(inside, 0.01 * np.sin(cols), np.nan)
    coefficients = np.array([0.0, 0.2, -0.1, 0.05, -0.03, 0.0])
    modes = ((0, 0), (1, 1), (1, -1), (2, 0), (2, -2), (2, 2))
    return FitView(fitted + residual, fitted, residual, coefficients, modes, 1, "waves", "test map", "circle")


def _off_grid(axes, value: float, fractions: tuple[float, ...]) -> float:
    """The first ``value * f`` more than 2 pixels from every horizontal grid line."""
    grid = axes.transData.transform([(0.0, t) for t in axes.get_yticks()])[:, 1]
    for fraction in fractions:
        y = value * fraction
        if np.min(np.abs(grid - axes.transData.transform((0.0, y))[1])) > 2:
            return y
    raise AssertionError(f"no point clear of the grid near {value}")


def test_maps_and_bars_show_the_data(tmp_path) -> None:
    view = _view()
    figure = fit_figure(view)
    image = saved(figure, tmp_path / "fit.png")
    measured_axes, fitted_axes, residual_axes, bars = figure.axes[:4]
    # measured and fitted share one scale: the largest |value| of both; the residual has its own
    bound = max(np.nanmax(np.abs(view.measured)), np.nanmax(np.abs(view.fitted)))
    shared, own = Normalize(-bound, bound), Normalize(-np.nanmax(np.abs(view.residual)), np.nanmax(np.abs(view.residual)))
    for row, col in ((11, 2), (3, 12), (20, 15), (12, 12)):
        assert_colour(pixel(image, measured_axes, col, row), colour(SIGNED_CMAP, shared, view.measured[row, col]),
                      f"measured ({row}, {col})")
        assert_colour(pixel(image, fitted_axes, col, row), colour(SIGNED_CMAP, shared, view.fitted[row, col]),
                      f"fitted ({row}, {col})")
        assert_colour(pixel(image, residual_axes, col, row), colour(SIGNED_CMAP, own, view.residual[row, col]),
                      f"residual ({row}, {col})")
    assert_colour(pixel(image, measured_axes, 0, 0), "white", "outside the aperture")  # NaN: background
    for k, value in enumerate(view.coefficients):
        if abs(value) > 0.02:  # inside the bar, and on the other side of zero
            assert_colour(pixel(image, bars, k, _off_grid(bars, value, (0.45, 0.6))), BAR_COLOUR, f"bar {k}")
            assert_colour(pixel(image, bars, k, _off_grid(bars, -value, (0.3, 0.4, 0.5))), "white", f"opposite bar {k}")
    labels = [t.get_text() for t in bars.get_xticklabels()]
    assert labels == [mode_label(j + 1, *nm) for j, nm in enumerate(view.modes)] and labels[3] == "Z4 defocus"
    assert all(a.get_title() for a in figure.axes[:4]) and figure.axes[0].get_xlabel() == "column, px"
    assert [a.get_ylabel() for a in figure.axes[4:7]] == ["wavefront, waves", "wavefront, waves", "residual, waves"]


def test_write_fit_figure_writes_the_png(tmp_path) -> None:
    path = write_fit_figure(_view(), tmp_path / "out.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
