"""Run the pipeline again on a recording: the same frames, the same or different fit settings.

With the recorded settings every result is recomputed on the fitter that ran it live (a ``qr``
stand-in while the configured map was being built, then the configured fitter), so a replay
reproduces the recorded coefficients; :attr:`ReplayedResult.difference_rms` says by how much,
and :attr:`ReplayedResult.residual_pv_difference` by how much the residual's peak-to-valley
moved (recordings made before results carried ``residual_pv`` have nothing to compare it with).
With other settings (another ``--config``) the fitters are built as those settings say,
synchronously.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wavestack.config import StationConfig, parse_station_config
from wavestack.pipeline import InputError
from wavestack.recording.reader import RecordingDamaged, RecordingReader
from wavestack.pipeline.instrument import InterferometerOutcome, SlopeOutcome
from wavestack.station import SetBatch, build_processor, json_ready


@dataclass(frozen=True, eq=False)
class ReplayedResult:
    """One recomputed result beside the recorded one.

    Attributes
    ----------
    index : int
        The station's set index.
    frame_ids : tuple of int
    processed : InterferometerOutcome or SlopeOutcome
        The recomputed outcome.
    recorded_coefficients : ndarray or None
        The live result's coefficients (None when it was invalid or not recorded).
    difference_rms : float or None
        RMS of recomputed minus recorded coefficients, waves.
    recorded_residual_pv : float or None
        The live result's residual peak-to-valley, waves (None when invalid, or recorded before
        results carried it).
    residual_pv_difference : float or None
        Recomputed minus recorded residual peak-to-valley, waves.
    affected_by_damage : bool
        This result may differ from the live one because of damage elsewhere: a set before it was
        not replayed (the processing carries state from set to set: the temporal unwrapper's
        reference phase, the aperture being confirmed, the carrier; ~1e-4 waves on the small
        station), or its recorded result row is damaged, so the fitter that ran live is unknown.
        Results not affected reproduce the live ones exactly.
    """

    index: int
    frame_ids: tuple[int, ...]
    processed: InterferometerOutcome | SlopeOutcome
    recorded_coefficients: np.ndarray | None
    difference_rms: float | None
    recorded_residual_pv: float | None = None
    residual_pv_difference: float | None = None
    affected_by_damage: bool = False

    def to_json(self) -> dict[str, object]:
        p = self.processed
        coefficients = [] if p.coefficients_waves is None else [float(c) for c in p.coefficients_waves]
        statistics = p.statistics
        return json_ready({"type": "result", "index": self.index, "frame_ids": list(self.frame_ids), "valid": p.valid,
                           "reason": p.reason, "coefficients": coefficients,
                           "fitter": p.fitter_kind, "fitter_fallback": p.fitter_fallback,
                           "unwrap_path": p.unwrap_path, "residual_rms": statistics.residual_rms,
                           "residual_pv": statistics.residual_pv, "pv": statistics.pv, "pvr": statistics.pvr,
                           "quality": {} if p.quality is None else p.quality.to_json(),
                           "difference_rms": self.difference_rms,
                           "residual_pv_difference": self.residual_pv_difference, "affected_by_damage": self.affected_by_damage})


@dataclass(frozen=True)
class SkippedSet:
    """A recorded set that could not be read intact, so was not replayed.

    Attributes
    ----------
    position : int
        Its position in the recording.
    index : int
        The station's set index (-1 when that too is damaged).
    reason : str
    """

    position: int
    index: int
    reason: str

    def to_json(self) -> dict[str, object]:
        return {"type": "skipped", "position": self.position, "index": self.index, "reason": self.reason}


def recorded_config(reader: RecordingReader, path: str | Path) -> StationConfig:
    """The configuration the recording was made with."""
    return parse_station_config(reader.config_toml, source=f"{path} (recorded configuration)")


def replay(reader: RecordingReader, config: StationConfig, *,
           same_settings: bool, batched_fits: bool = False) -> Iterator[ReplayedResult | SkippedSet]:
    """Recompute every intact recorded set; a damaged one is yielded as a :class:`SkippedSet`.

    Parameters
    ----------
    reader : RecordingReader
    config : StationConfig
        Settings to process with (the recorded ones, or others).
    same_settings : bool
        Reproduce each result's live fitter (the recorded settings).
    batched_fits : bool
        Fit the maps that share a fitter in batches (:class:`~wavestack.station.SetBatch`): the same
        results to the float32 operator's rounding (~1e-6 waves), not bit for bit the live ones.

    Yields
    ------
    ReplayedResult or SkippedSet
        In recording order; after the last, ``reader.damage`` lists every damaged part.
    """
    recorded = reader.results()
    missing = [key for key in ("valid", "fitter", "coefficients") if "index" in recorded and key not in recorded]
    if missing:
        raise InputError(f"{reader.path}: malformed station recording: result columns {missing} missing "
                         "(expected beside 'index')")
    rows = {int(i): k for k, i in enumerate(recorded.get("index", []))}
    processor = build_processor(config)  # every fitter built at once, as the live ones were
    batch: SetBatch[_Read] = SetBatch(processor, batched=batched_fits)
    gap = False
    rows_lost = any(d.part == "results" for d in reader.damage)
    for position in range(reader.n_sets):
        set_index = int(reader.set_indices[position])
        try:
            frames = reader.read_set(position)
        except RecordingDamaged as error:
            yield from (_compared(read, outcome, recorded) for read, outcome in batch.flush())
            yield SkippedSet(position, set_index, str(error))
            gap = True
            continue
        row = rows.get(set_index)
        method = None
        if same_settings and row is not None and recorded["fitter"][row]:
            method = str(recorded["fitter"][row])
        read = _Read(set_index, tuple(f.frame_id for f in frames), row, gap or (rows_lost and row is None))
        done = batch.add([f.pixels for f in frames], read, fitter_method=method)
        yield from (_compared(r, outcome, recorded) for r, outcome in done)
    yield from (_compared(read, outcome, recorded) for read, outcome in batch.flush())


@dataclass(frozen=True)
class _Read:
    """What replay keeps of a set while it waits for its fit."""

    index: int
    frame_ids: tuple[int, ...]
    row: int | None
    affected_by_damage: bool


def _compared(read: _Read, processed: InterferometerOutcome | SlopeOutcome,
              recorded: dict[str, np.ndarray]) -> ReplayedResult:
    """A recomputed outcome beside its recorded result row."""
    row = read.row
    live = None if row is None or not recorded["valid"][row] else np.asarray(recorded["coefficients"][row])
    difference = None
    found = processed.coefficients_waves
    if live is not None and found is not None and live.shape == found.shape:
        difference = float(np.sqrt(np.mean((found - live) ** 2)))
    live_pv = None
    if live is not None and "residual_pv" in recorded:  # a column since results carry it
        live_pv = float(recorded["residual_pv"][row])
    pv_difference = None
    if live_pv is not None and processed.valid:
        pv_difference = float(processed.residual_pv - live_pv)
    return ReplayedResult(read.index, read.frame_ids, processed, live, difference, live_pv, pv_difference,
                          read.affected_by_damage)
