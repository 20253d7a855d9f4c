"""Sets of a recording processed with one batched refit per run of sets that share a fitter.

:meth:`~wavestack.pipeline.instrument.InterferometerProcessor.prepare` runs the stages before the fit set after set (they carry state);
the prepared maps that share a fitter are then fitted together by ``Fitter.fit_many`` and each
finished by :meth:`~wavestack.pipeline.instrument.InterferometerProcessor.finish`. A run (a *group*) ends where the fitter changes, where a
set adopts a new aperture, at a set that could not be read, at :data:`GROUP_SETS` maps, and at
the end: so the groups, and therefore the numbers, depend only on the sets since the last
adoption, and a block of a recording that starts at an adoption is fitted exactly as the same
sets of the whole recording are.

What it changes: ``fit_many`` projects a stack with one matrix product where ``fit`` makes one
product per map; with the station's float32 operators the two round differently (measured on the
small station: coefficients within 7.4e-7 waves, residual RMS within 5e-5 waves, from the
``|w|^2 - c.Gc`` identity in float32), so the batched path is an option
(``replay(..., batched_fits=True)``), not what the live station or ``wavestack replay`` runs.
The carrier method, whose next frame depends on this frame's fit (an invalid fit makes it look for
its carrier afresh), and the Shack-Hartmann processor are processed set by set; so is a map with
pixels the quality mask left out (``fit_many`` fits such a map on its own).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final, Generic, TypeVar

import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline import FitResult, InvalidFrame
from wavestack.pipeline.instrument import InterferometerOutcome, InterferometerProcessor, PreparedSet
from wavestack.pipeline.instrument import ShackHartmannProcessor, SlopeOutcome

#: Most maps fitted in one batch (~256 kB each on the small station's fit grid).
GROUP_SETS: Final = 16

Tag = TypeVar("Tag")


@dataclass(frozen=True)
class _Waiting(Generic[Tag]):
    tag: Tag
    prepared: PreparedSet


class SetBatch(Generic[Tag]):
    """Feeds sets to a processor and hands back their outcomes, in order, as groups finish.

    Parameters
    ----------
    processor : InterferometerProcessor or ShackHartmannProcessor
    group_sets : int
        Most maps per batched fit.
    batched : bool
        False: every set through the processor's ``process`` as it comes (the live station's path).

    Example
    -------
    ::

        batch = SetBatch(processor)
        for position, frames in enumerate(sets):
            for position_done, outcome in batch.add(frames, position):
                ...
        for position_done, outcome in batch.flush():
            ...
    """

    def __init__(self, processor: InterferometerProcessor | ShackHartmannProcessor, *, group_sets: int = GROUP_SETS,
                 batched: bool = True) -> None:
        if group_sets < 1:
            raise ValueError(f"group_sets: expected at least 1, got {group_sets}")
        self._processor = processor
        self._group_sets = group_sets
        self._batched = batched and isinstance(processor, InterferometerProcessor) and processor.settings.method == "psi"
        self._waiting: list[_Waiting[Tag]] = []

    def add(self, frames: Sequence[NDArray[np.generic]], tag: Tag, *, fitter_method: str | None = None
            ) -> list[tuple[Tag, InterferometerOutcome | SlopeOutcome]]:
        """Process one set up to its fit; returns the (tag, outcome) pairs finished meanwhile, in order."""
        if not self._batched:
            return [(tag, self._processor.process(frames, fitter_method=fitter_method))]
        assert isinstance(self._processor, InterferometerProcessor)
        prepared = self._processor.prepare(frames, fitter_method=fitter_method)
        done = []
        if prepared.outcome is None and self._ends_group(prepared):
            done = self.flush()
        self._waiting.append(_Waiting(tag, prepared))
        return done

    def flush(self) -> list[tuple[Tag, InterferometerOutcome | SlopeOutcome]]:
        """Fit and finish every waiting set (at a damaged set, at the end)."""
        waiting, self._waiting = self._waiting, []
        to_fit = [w.prepared for w in waiting if w.prepared.outcome is None]
        fits, fit_s = _fit_group(to_fit)
        assert isinstance(self._processor, InterferometerProcessor) or not waiting
        done = []
        for item in waiting:
            fit = fits.get(id(item.prepared))
            outcome = (item.prepared.outcome if fit is None
                       else self._processor.finish(item.prepared, fit, fit_s))  # type: ignore[union-attr]
            assert outcome is not None
            done.append((item.tag, outcome))
        return done

    def _ends_group(self, prepared: PreparedSet) -> bool:
        """Whether ``prepared`` starts a new group (module notes)."""
        group = [w.prepared for w in self._waiting if w.prepared.outcome is None]
        if not group:
            return False
        assert prepared.choice is not None and group[-1].choice is not None
        return (prepared.aperture_changed or len(group) >= self._group_sets
                or prepared.choice.fitter is not group[-1].choice.fitter)


def _fit_group(group: Sequence[PreparedSet]) -> tuple[dict[int, FitResult | InvalidFrame], float]:
    """Each prepared map's fit (by ``id``) from one ``fit_many``, and each map's share of its time.

    A group of one map, and every map of a batch that refuses (one map with too few finite
    samples), is fitted alone (``Fitter.fit``).
    """
    if not group:
        return {}, 0.0
    fitter = group[0].choice.fitter  # type: ignore[union-attr]
    maps = [p.to_fit for p in group]
    tick = time.perf_counter()
    fits: list[FitResult | InvalidFrame] | None = None
    if len(maps) > 1:
        try:
            fits = list(fitter.fit_many(np.stack(maps), nan_policy="omit", residual=True))
        except InvalidFrame:
            fits = None
    if fits is None:
        fits = [_fit_alone(fitter, m) for m in maps]
    share = (time.perf_counter() - tick) / len(group)
    return {id(p): f for p, f in zip(group, fits)}, share


def _fit_alone(fitter: object, waves: NDArray[np.floating] | None) -> FitResult | InvalidFrame:
    try:
        return fitter.fit(waves, nan_policy="omit", residual=True)  # type: ignore[attr-defined]
    except InvalidFrame as error:
        return error
