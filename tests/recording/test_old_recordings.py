"""Recordings made before results carried ``residual_pv``, the frame and set counters and (format
version 3) PV, PVr and the data-quality counts still read and replay.

The file is written here, by the same :class:`RecordingWriter`, with the result columns the station
wrote until then (``COLUMNS_BEFORE_COUNTERS``), on frames of the simulated station, so replay has
real sets to recompute, and stamped with format version 2 (its header checksum made again). A file
kept from an older wavestack would hold several megabytes of frames; the writer and the layout did
not change, only the row and the version.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path

import h5py
import numpy as np
import pytest

from wavestack import __version__
from wavestack.cli import main
from wavestack.config import StationConfig, load_station_config
from wavestack.recording import FRAME_METADATA, RecordingReader, RecordingWriter, conventions, recorded_config
from wavestack.recording import recording_row, replay
from wavestack.recording.format import RowValue, header_crc32
from wavestack.station import Counters, CycleRecord, StationResult

SMALL = Path(__file__).resolve().parents[1] / "configs" / "station-small.toml"


#: The station's result columns before ``residual_pv`` and the counters were columns.
COLUMNS_BEFORE_COUNTERS = ("index", "valid", "reason", "frame_ids", "exposure_time_ns", "latency_ms", "coefficients",
                           "residual_rms", "fitter", "fitter_fallback", "aperture_id", "aperture_changed",
                           "unwrap_path", "truth_error_rms", "sent_to_plc")


def _row_before_counters(result: StationResult, modes: int, frames_per_set: int) -> dict[str, RowValue]:
    """The station's result row as it was before ``residual_pv`` and the counters were columns."""
    row = recording_row(result, modes, frames_per_set)
    return {key: row[key] for key in COLUMNS_BEFORE_COUNTERS}


def _old_recording(path: Path, config: StationConfig, station_factory) -> list[StationResult]:
    fps, modes = config.processing.frames_per_set, config.processing.modes
    empty = StationResult.invalid(0, "", Counters.zero(fps), ordering=config.processing.ordering)
    writer = RecordingWriter(path, config_toml=config.text, conventions=conventions(config),
                             software_version=__version__, frame_shape=(256, 256), frame_dtype=np.uint16,
                             frames_per_set=fps, metadata_keys=FRAME_METADATA,
                             result_template=_row_before_counters(empty, modes, fps))
    station, _ = station_factory(config)
    live: list[StationResult] = []

    def record(cycle: CycleRecord) -> None:
        live.append(cycle.result)
        if cycle.frames:
            writer.append_set(cycle.result.index, cycle.frames)
            if cycle.new_aperture_mask is not None:
                writer.append_aperture(cycle.result.index, cycle.new_aperture_mask)
        writer.append_result(_row_before_counters(cycle.result, modes, fps))

    try:
        station.run(stop=threading.Event(), on_result=record, max_results=4)
    finally:
        writer.close()
    with h5py.File(path, "r+") as file:  # as version 2 wrote it: the same layout and checksums
        file.attrs["format_version"] = 2
        file.attrs["header_crc32"] = header_crc32(file.attrs, file["conventions"].attrs)
    return live


def test_the_new_row_only_adds_columns() -> None:
    config = load_station_config(SMALL)
    fps, modes = config.processing.frames_per_set, config.processing.modes
    empty = StationResult.invalid(0, "", Counters.zero(fps), ordering=config.processing.ordering)
    new = recording_row(empty, modes, fps)
    assert set(new) - set(COLUMNS_BEFORE_COUNTERS) == {
        "residual_pv", "frames_acquired", "frames_processed", "frames_dropped", "frames_pending", "sets_assembled",
        "sets_processed", "sets_dropped", "sets_pending",
        # format version 3: the robust figures and the data-quality counts
        "pv", "pvr", "quality_inside", "quality_used", "quality_low_modulation", "quality_saturated",
        "quality_untrusted_order", "quality_clipped", "quality_rim",
        # and, in the same version, the live surface figures and the drawing's verdict
        "surface_sag_nm", "surface_irr_nm", "surface_rsi_nm", "surface_rmst_nm", "surface_rmsi_nm", "surface_rmsa_nm",
        "surface_pvr_nm", "spec_passed", "spec_limiting"}
    assert set(COLUMNS_BEFORE_COUNTERS) <= set(new)


def test_an_old_recording_reads_and_replays(station_factory, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    config = load_station_config(SMALL)
    path = tmp_path / "old.h5"
    live = _old_recording(path, config, station_factory)
    with RecordingReader(path) as reader:
        table = reader.results()
        assert reader.format_version == 2 and not reader.damage
        assert "residual_pv" not in table and "frames_acquired" not in table and "pvr" not in table
        assert reader.n_results == 4
        replayed = list(replay(reader, recorded_config(reader, path), same_settings=True))
    with_sets = [r for r in live if r.frame_ids]  # 4, unless a loaded machine lost a set
    compared = sum(r.valid for r in with_sets)
    assert compared >= 2, [r.reason for r in live]
    for again, original in zip(replayed, with_sets, strict=True):
        if original.valid:
            np.testing.assert_allclose(again.processed.coefficients_waves, original.coefficients, rtol=0, atol=1e-12)
            assert again.processed.residual_pv > 0 and again.processed.statistics.pvr > 0  # the replay computes them
        assert again.recorded_residual_pv is None and again.residual_pv_difference is None  # nothing to compare

    assert main(["replay", str(path)]) == 0
    text = capsys.readouterr().out
    assert f"{len(with_sets)} results replayed" in text and f"; {compared} compared" in text
    assert "residual pv not compared" in text
    assert main(["replay", str(path), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert summary["compared"] == compared and summary["compared_residual_pv"] == 0
    assert summary["max_residual_pv_difference"] is None
