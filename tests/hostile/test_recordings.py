"""Hostile recordings: a file that declares what it does not hold is refused before anything is allocated.

A few kilobytes of HDF5 can declare 2e8 sets (their chunks never written, read as zeros): the
reader believed it and planned ~50 GB. These files are made by resizing a small real recording's
datasets with h5py, as anyone can.
"""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import h5py
import numpy as np
import pytest

from wavestack.batch.plan import plan_recording
from wavestack.cli import EXIT_BAD_INPUT, main
from wavestack.drivers.frames import Frame
from wavestack.pipeline import InputError
from wavestack.recording import RecordingReader, RecordingWriter

SHAPE, FPS = (8, 9), 2
DECLARED = 200_000_000


def _record(path: Path, n_sets: int = 3) -> Path:
    with RecordingWriter(path, config_toml="x = 1", conventions={"ordering": "noll", "modes": 5},
                         software_version="t", frame_shape=SHAPE, frame_dtype=np.uint16,
                         frames_per_set=FPS) as writer:
        for s in range(n_sets):
            if s == 0:
                writer.append_aperture(0, np.ones(SHAPE, bool))
            frames = [Frame(2 * s + j, s, s, np.full(SHAPE, s, np.uint16), {}) for j in range(FPS)]
            writer.append_set(s, frames)
            writer.append_result({"index": s, "valid": True, "coefficients": np.arange(3) * s, "fitter": "qr"})
    return path


def _declare_sets(path: Path, count: int) -> Path:
    """Every per-set dataset, the committed count and the set CRCs resized to ``count`` rows (never written)."""
    with h5py.File(path, "r+") as f:
        for name in ("sets/pixels", "sets/set_index", "sets/frame_id", "sets/host_time_ns", "sets/device_timestamp",
                     "integrity/set_crc32"):
            f[name].resize(count, axis=0)
        f["committed_counts"][0] = count
    return path


def test_a_recording_declaring_2e8_sets_is_refused_before_allocating(tmp_path: Path) -> None:
    path = _declare_sets(_record(tmp_path / "hostile.h5"), DECLARED)
    assert path.stat().st_size < 1 << 20  # the whole file: a few hundred kilobytes
    tracemalloc.start()
    try:
        with pytest.raises(InputError, match=rf"hostile.h5.*declares {DECLARED} rows"):
            RecordingReader(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 64 << 20  # nothing of the declared size (1.6 GB per int64 column) was made


def test_replay_of_it_is_one_line_and_exit_2(tmp_path: Path, capsys) -> None:
    path = _declare_sets(_record(tmp_path / "hostile.h5"), DECLARED)
    assert main(["replay", str(path)]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "hostile.h5" in err and "declares" in err


def test_a_frame_beyond_the_memory_budget_is_refused(tmp_path: Path) -> None:
    path = _record(tmp_path / "wide.h5")
    with h5py.File(path, "r+") as f:  # frames declared 200000 x 200000 (a set: 160 GB), chunks unwritten
        del f["sets/pixels"], f["apertures/mask"]
        f.create_dataset("sets/pixels", shape=(3, FPS, 200_000, 200_000), dtype=np.uint16,
                         chunks=(1, FPS, 256, 256), maxshape=(None, FPS, 200_000, 200_000))
        f.create_dataset("apertures/mask", shape=(1, 200_000, 200_000), dtype=bool, chunks=(1, 256, 256))
    with pytest.raises(InputError, match="one recorded set.*memory"):
        RecordingReader(path)


def test_a_truncated_recording_is_damage_not_a_refusal(tmp_path: Path) -> None:
    path = _record(tmp_path / "cut.h5", n_sets=40)
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * 0.8)])
    try:
        reader = RecordingReader(path)
    except InputError as error:  # a damaged header is refused; a declaration it holds is never the reason
        assert "declares" not in str(error)
    else:
        with reader:
            assert reader.n_sets > 0


def test_one_hostile_file_is_planned_as_its_own_unreadable_task_named(tmp_path: Path) -> None:
    good = _record(tmp_path / "good.h5")
    hostile = _declare_sets(_record(tmp_path / "hostile.h5"), DECLARED)
    plans = [plan_recording(str(p), None) for p in (good, hostile)]
    assert [p.kind for p in plans] == ["station", "unreadable"]
    assert "hostile.h5" in plans[1].tasks[0].message and "declares" in plans[1].tasks[0].message
    assert plans[0].sets == 3
