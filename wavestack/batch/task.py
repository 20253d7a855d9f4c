"""The task a worker runs: a path and positions in, plain rows out (:class:`~wavestack.batch.rows.TaskOutcome`).

The worker opens the recording itself (h5py objects cannot travel between processes), read-only,
so any number of workers may read one file. A station block is replayed by
:func:`wavestack.recording.replay` itself, on a view of the reader that shows only the block's
sets, so a row is by construction what ``wavestack replay`` computes for that set.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wavestack.batch.plan import Task
from wavestack.batch.rows import STAGES, ResultRow, SkippedItem, TaskOutcome, station_row
from wavestack.config import ProcessingSettings, parse_station_config
from wavestack.loop import MAP_KIND, read_campaign
from wavestack.pipeline import FitResult, Fitter, InputError, build_fitter
from wavestack.recording import RecordingDamaged, RecordingReader, recorded_config, replay
from wavestack.recording.replay import SkippedSet

logger = logging.getLogger(__name__)


def fit_block(fitter: Fitter, frames: NDArray[np.floating], **kwargs: Any) -> list[FitResult]:
    """Fit a stack of maps that share the fitter's aperture in one batched refit (``Fitter.fit_many``).

    Parameters
    ----------
    fitter : Fitter
    frames : ndarray, shape (K, rows, cols)
    **kwargs
        As for ``Fitter.fit`` (``nan_policy``, ``residual``).

    Returns
    -------
    list of FitResult
        One per map, in order.

    Examples
    --------
    >>> from wavestack.pipeline import build_fitter
    >>> yy, xx = np.mgrid[-1:1:32j, -1:1:32j]
    >>> fitter = build_fitter(xx**2 + yy**2 <= 1, method="circle", modes=6)
    >>> [len(r.coefficients) for r in fit_block(fitter, np.zeros((2, 32, 32)))]
    [6, 6]
    """
    return list(fitter.fit_many(frames, **kwargs))


def analyse(task: Task) -> TaskOutcome:
    """Run one task (see :class:`~wavestack.batch.plan.Task`); never raises for a bad file.

    A recording that cannot be opened or processed gives an outcome with ``error`` set; an
    exception that is not about the file (a bug, memory) propagates to the client.
    """
    tick = time.perf_counter()
    try:
        if task.kind == "station":
            outcome = _station(task)
        elif task.kind == "polish":
            outcome = _polish(task)
        else:
            outcome = TaskOutcome(error=task.message)
    except InputError as error:
        outcome = TaskOutcome(error=str(error))
    return TaskOutcome(**{**outcome.__dict__, "wall_s": time.perf_counter() - tick})


class _BlockView:
    """The part of a :class:`RecordingReader` that :func:`replay` uses, limited to positions ``start`` ..
    ``stop - 1``; remembers each set's first host time."""

    def __init__(self, reader: RecordingReader, start: int, stop: int) -> None:
        self._reader, self._start = reader, start
        self.path = reader.path
        self.n_sets = stop - start
        self.set_indices = reader.set_indices[start:stop]
        self.times_ns: dict[int, int] = {}

    @property
    def damage(self) -> tuple[Any, ...]:
        return self._reader.damage

    def results(self) -> dict[str, NDArray[Any]]:
        return self._reader.results()

    def read_set(self, i: int) -> tuple[Any, ...]:
        frames = self._reader.read_set(self._start + i)
        self.times_ns[i] = int(frames[0].host_time_ns)
        return frames


def _station(task: Task) -> TaskOutcome:
    with RecordingReader(task.path) as reader:
        config = (recorded_config(reader, task.path) if task.config_text is None
                  else parse_station_config(task.config_text, source=f"{task.path} (batch settings)"))
        stop = task.stop + 1 if task.check_next else task.stop
        view = _BlockView(reader, task.start, stop)
        rows: list[ResultRow] = []
        skipped: list[SkippedItem] = []
        stage_s = dict.fromkeys(STAGES, 0.0)
        boundary_ok: bool | None = None
        items = replay(view, config, same_settings=task.config_text is None)  # type: ignore[arg-type]
        for local, item in enumerate(items):
            position = task.start + local
            if task.check_next and position == task.stop:
                boundary_ok = not isinstance(item, SkippedSet) and bool(getattr(item.processed, "aperture_changed",
                                                                                  False))
                break
            if isinstance(item, SkippedSet):
                skipped.append(SkippedItem(position, item.index, item.reason))
                continue
            for stage, seconds in getattr(item.processed, "timings_s", {}).items():
                if stage in stage_s:
                    stage_s[stage] += seconds
            rows.append(station_row(task.path, position, view.times_ns[local], item))
        return TaskOutcome(tuple(rows), tuple(skipped), tuple(str(d) for d in reader.damage), tuple(reader.notes),
                           boundary_ok=boundary_ok, stage_s=tuple(stage_s[s] for s in STAGES))


def _polish(task: Task) -> TaskOutcome:
    """Refit a polishing campaign's intact surface maps (nm) on its aperture, in one block.

    The record is read by the loop kernel's reader: every map record whose CRC-32 holds is
    refitted; a damaged one is named in the outcome's damage.
    """
    settings = (ProcessingSettings() if task.config_text is None
                else parse_station_config(task.config_text, source=f"{task.path} (batch settings)").processing)
    try:
        log = read_campaign(Path(task.path))
    except InputError as error:
        return TaskOutcome(error=f"{task.path}: polish campaign record unreadable ({error})")
    records = log.of_kind(MAP_KIND)
    if not records or "aperture_mask" not in records[0].arrays:
        return TaskOutcome(error=f"{task.path}: polish campaign record without an intact first surface map")
    mask = np.asarray(records[0].arrays["aperture_mask"], dtype=bool)
    chosen = records[task.start:task.stop]
    maps = [np.asarray(r.arrays["map"], dtype=np.float64) for r in chosen]
    positions = list(range(task.start, task.start + len(chosen)))
    times = [float(r.fields.get("exposure_unix_s") or np.nan) for r in records]
    fit = settings.fit_settings()
    fitter = build_fitter(mask, method=fit.method, modes=fit.modes, ordering=fit.ordering, remove=fit.remove,
                          mesh_vertices=fit.mesh_vertices, fallback="qr" if fit.method in ("csf-qcm", "conformal")
                          else None, obscuration=fit.obscuration)
    tick = time.perf_counter()
    fits = fit_block(fitter, np.stack(maps), nan_policy="omit", residual=True) if maps else []
    fit_s = time.perf_counter() - tick
    rows = [_polish_row(task.path, p, times, mask, fitter, r) for p, r in zip(positions, fits)]
    return TaskOutcome(tuple(rows), (), log.damage, stage_s=(0.0, 0.0, 0.0, fit_s))


def _polish_row(path: str, position: int, times: Sequence[float], mask: NDArray[np.bool_], fitter: Any,
                fit: FitResult) -> ResultRow:
    d = fitter.diagnostics
    time_s = float(times[position]) if position < len(times) and np.isfinite(times[position]) else 0.0
    return ResultRow(recording=path, position=position, index=position, time_ns=int(round(time_s * 1e9)),
                     frame_ids=(), valid=True, reason="", coefficients=tuple(float(c) for c in fit.coefficients),
                     units="nm", residual_rms=float(fit.residual_rms), residual_pv=float(fit.residual_pv or np.nan),
                     fitter=str(d.method), fitter_fallback=False, unwrap_path="", aperture_id=0,
                     aperture_changed=position == 0, aperture_pixels=int(mask.sum()), aperture_topology=str(d.topology),
                     gram_condition=float(d.gram_condition), flips=-1 if d.flips is None else int(d.flips),
                     max_beltrami=float(np.nan if d.max_beltrami is None else d.max_beltrami),
                     difference_rms=float("nan"), residual_pv_difference=float("nan"), affected_by_damage=False)
