"""``wavestack replay FILE.h5 --plots DIR``: what a recording shows over time.

* ``coefficients.png``: the leading coefficients of every replayed result against the station's
  set index, a dashed line at every set that started a new aperture (where a jump is expected);
* ``latency.png``: the histogram of the live latency the recording kept (exposure to result);
* ``last-map.png``: the wavefront of the last valid result, in false colour.

:class:`ReplayCollector` gathers what they need while the replay runs (one small row per result
and the last map), then freezes it into a :class:`ReplaySeries`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from wavestack.figures.drawing import BAR_COLOUR, aperture_outline, map_panel, mode_label, new_figure, save_figure
from wavestack.pipeline import mode_list, zernike_basis
from wavestack.recording.replay import ReplayedResult, SkippedSet

__all__ = ["LEADING_MODES", "ReplayCollector", "ReplaySeries", "coefficient_figure", "last_map_figure",
           "latency_figure", "write_replay_figures"]

#: Coefficients drawn in the time series: the modes after piston and tilt, up to primary spherical (Noll 4-11).
LEADING_MODES = slice(3, 11)
_DISK_PX = 128  # grid of a map drawn from coefficients alone (a Shack-Hartmann result has no pixel map)


@dataclass(frozen=True, eq=False)
class ReplaySeries:
    """What the replay figures show.

    Attributes
    ----------
    source : str
        The recording's path.
    indices : ndarray of int, shape (K,)
        Station set index of every replayed result.
    coefficients : ndarray, shape (K, M)
        Waves; NaN rows for invalid results.
    modes : tuple of (n, m)
    first_index : int
        Index of the first mode in its ordering (1 for Noll).
    aperture_changes : ndarray of int
        Set indices at which a new aperture started.
    latency_ms : ndarray
        The live latency of each recorded result, ms (empty when the recording has none).
    last_map : ndarray, shape (H, W), or None
        The last valid result's wavefront, waves, NaN outside.
    last_index : int or None
        Its set index.
    """

    source: str
    indices: NDArray[np.int64]
    coefficients: NDArray[np.float64]
    modes: tuple[tuple[int, int], ...]
    first_index: int
    aperture_changes: NDArray[np.int64]
    latency_ms: NDArray[np.float64]
    last_map: NDArray[np.float64] | None
    last_index: int | None


def _disk_map(coefficients: NDArray[np.float64], modes: Sequence[tuple[int, int]]) -> NDArray[np.float64]:
    """The wavefront of unit-RMS circle coefficients on a disk of :data:`_DISK_PX` pixels across."""
    rows, cols = np.indices((_DISK_PX, _DISK_PX))
    half = (_DISK_PX - 1) / 2
    x, y = (cols - half) / half, (half - rows) / half
    inside = np.hypot(x, y) <= 1.0
    values = np.full((_DISK_PX, _DISK_PX), np.nan)
    values[inside] = zernike_basis(list(modes), x[inside], y[inside]) @ coefficients
    return values


class ReplayCollector:
    """Gathers a replay's results for the figures; :meth:`series` freezes them.

    Example
    -------
    >>> collector = ReplayCollector()
    >>> collector.series("none.h5", {}, {"ordering": "noll"}).indices.size
    0
    """

    def __init__(self) -> None:
        self._indices: list[int] = []
        self._rows: list[NDArray[np.float64] | None] = []
        self._changes: list[int] = []
        self._last: tuple[int, Any] | None = None

    def add(self, item: ReplayedResult | SkippedSet) -> None:
        """Keep one replayed result (a skipped set leaves a gap)."""
        if isinstance(item, SkippedSet):
            return
        p = item.processed
        coefficients = p.coefficients_waves if p.valid else None
        self._indices.append(item.index)
        self._rows.append(None if coefficients is None else np.asarray(coefficients, dtype=np.float64))
        if p.aperture_changed:
            self._changes.append(item.index)
        if coefficients is not None:
            self._last = (item.index, p)

    def series(self, source: str, recorded: Mapping[str, NDArray[Any]], conventions: Mapping[str, Any]) -> ReplaySeries:
        """The frozen series.

        Parameters
        ----------
        source : str
        recorded : mapping
            The recording's result columns (``RecordingReader.results()``); ``latency_ms`` is used.
        conventions : mapping
            The recording's conventions (``ordering``, ``first_index``).
        """
        width = max((row.size for row in self._rows if row is not None), default=0)
        table = np.full((len(self._rows), width), np.nan)
        for k, row in enumerate(self._rows):
            if row is not None:
                table[k, : row.size] = row
        modes = tuple(mode_list(str(conventions.get("ordering", "noll")), width))
        last_map, last_index = None, None
        if self._last is not None:
            last_index, outcome = self._last
            waves = getattr(outcome, "waves", None)
            last_map = (np.asarray(waves, dtype=np.float64) if waves is not None
                        else _disk_map(np.asarray(outcome.coefficients_waves, dtype=np.float64), modes))
        latency = np.asarray(recorded.get("latency_ms", np.empty(0)), dtype=np.float64)
        return ReplaySeries(source=source, indices=np.asarray(self._indices, dtype=np.int64), coefficients=table,
                            modes=modes, first_index=int(conventions.get("first_index", 1)),
                            aperture_changes=np.asarray(self._changes, dtype=np.int64),
                            latency_ms=latency[np.isfinite(latency)], last_map=last_map, last_index=last_index)


def coefficient_figure(series: ReplaySeries) -> Figure:
    """The leading coefficients (:data:`LEADING_MODES`) against set index, aperture changes dashed.

    ``figure.axes[0]`` holds one line per mode, in mode order, then one vertical line per change.
    """
    figure = new_figure(12.0, 5.0)
    axes = figure.add_subplot()
    shown = range(series.coefficients.shape[1])[LEADING_MODES]
    for k in shown:
        axes.plot(series.indices, series.coefficients[:, k], marker=".", linewidth=1.0,
                  label=mode_label(series.first_index + k, *series.modes[k]))
    for change in series.aperture_changes:
        axes.axvline(change, color="black", linestyle="--", linewidth=0.9)
    axes.set_xlabel("set index")
    axes.set_ylabel("coefficient, waves")
    axes.set_title(f"{series.source}: leading coefficients of {series.indices.size} replayed results; "
                   f"dashed: {series.aperture_changes.size} aperture changes", fontsize=10)
    if len(shown):
        axes.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.0, 0.5))
    axes.grid(linewidth=0.3)
    return figure


def latency_figure(series: ReplaySeries, bins: int = 30) -> Figure:
    """The histogram of the recorded live latency, ms (``figure.axes[0]``, ``bins`` equal bins)."""
    figure = new_figure(8.0, 5.0)
    axes = figure.add_subplot()
    latency = series.latency_ms
    if latency.size:
        axes.hist(latency, bins=bins, color=BAR_COLOUR)
        median, p99 = np.percentile(latency, [50, 99])
        summary = f"median {median:.1f} ms, p99 {p99:.1f} ms over {latency.size} results"
    else:
        summary = "no latency recorded"
    axes.set_xlabel("latency, ms (exposure to result, live)")
    axes.set_ylabel("results")
    axes.set_title(f"{series.source}: latency, {summary}", fontsize=10)
    return figure


def last_map_figure(series: ReplaySeries) -> Figure:
    """The last valid result's wavefront (``figure.axes[0]``, its own symmetric scale), or a note if none."""
    figure = new_figure(7.0, 6.0)
    axes = figure.add_subplot()
    if series.last_map is None:
        axes.set_title(f"{series.source}: no valid result to show")
        axes.set_xlabel("column, px")
        axes.set_ylabel("row, px")
        return figure
    data = series.last_map
    finite = data[np.isfinite(data)]
    map_panel(figure, axes, data, unit="wavefront, waves",
              title=f"{series.source}: result {series.last_index}, RMS {np.std(finite):.4f} waves")
    aperture_outline(axes, np.isfinite(data))
    return figure


def write_replay_figures(series: ReplaySeries, folder: str | Path) -> list[Path]:
    """Write ``coefficients.png``, ``latency.png`` and ``last-map.png`` into ``folder``; returns the paths."""
    target = Path(folder)
    return [save_figure(coefficient_figure(series), target / "coefficients.png"),
            save_figure(latency_figure(series), target / "latency.png"),
            save_figure(last_map_figure(series), target / "last-map.png")]
