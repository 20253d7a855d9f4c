"""Station recording: round trip, refusals, bad files, and a writer killed with SIGKILL."""

from __future__ import annotations

import logging
import signal
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wavestack.drivers.frames import Frame
from wavestack.pipeline import InputError
from wavestack.recording import FORMAT_VERSION, RecordingReader, RecordingWriter

SHAPE = (6, 7)
FPS = 3
CONFIG = '[pzt]\nurl = "sim://"\nmax_v = 75.0\n'
CONVENTIONS = {"zernike_order": "noll", "wavelength_nm": 632.8, "n_modes": 15}


def _pixels(set_index: int, j: int) -> np.ndarray:
    """Deterministic, distinct per set and frame (uint16 wraps are intended)."""
    return ((np.arange(SHAPE[0] * SHAPE[1]).reshape(SHAPE) * 7 + 1000 * set_index + j) % 65536).astype(np.uint16)


def _frames(set_index: int) -> list[Frame]:
    frames = []
    for j in range(FPS):
        metadata: dict[str, Any] = {"pzt_commanded_v": 1.25 * j + set_index, "pixel_format": "Mono12"}
        if j != 1:  # frame 1 has no readback: stored as NaN, restored as absent
            metadata["pzt_readback_v"] = 1.25 * j + set_index - 0.01
        frames.append(Frame(10 * set_index + j, 5_000 + set_index, 77 * set_index + j, _pixels(set_index, j),
                            metadata))
    return frames


def _result(set_index: int) -> dict[str, Any]:
    return {"set_index": set_index, "rms_nm": 0.5 * set_index, "valid": set_index % 2 == 0,
            "coefficients": np.linspace(0.0, 1.0, 15) * set_index, "method": "csf-qcm" if set_index else "",
            "note": f"ensemble {set_index} — λ/20\x00"}  # a trailing NUL must survive


def _writer(path: Path, **kwargs: Any) -> RecordingWriter:
    return RecordingWriter(path, config_toml=CONFIG, conventions=CONVENTIONS, software_version="0.1.0",
                           frame_shape=SHAPE, frame_dtype=np.uint16, frames_per_set=FPS, **kwargs)


def test_round_trip_sets_metadata_apertures_results(tmp_path: Path) -> None:
    path = tmp_path / "run.h5"
    set_indices = [0, 1, 2, 4, 5]  # set 3 was dropped by the station: gaps are allowed
    first_mask = np.zeros(SHAPE, bool)
    first_mask[1:5, 1:6] = True
    second_mask = ~first_mask
    with _writer(path, chunk_sets=2) as writer:
        writer.append_aperture(0, first_mask)
        for s in set_indices:
            if s == 4:
                writer.append_aperture(4, second_mask)
            writer.append_set(s, _frames(s))
            writer.append_result(_result(s))
    writer.close()  # idempotent

    with RecordingReader(path) as reader:
        assert reader.closed_cleanly
        assert reader.format_version == FORMAT_VERSION
        assert reader.config_toml == CONFIG
        assert reader.conventions == CONVENTIONS
        assert type(reader.conventions["n_modes"]) is int
        assert reader.software_version == "0.1.0"
        assert (reader.n_sets, reader.frames_per_set, reader.frame_shape) == (5, FPS, SHAPE)
        assert reader.set_indices.tolist() == set_indices
        assert reader.metadata_keys == ("pzt_commanded_v", "pzt_readback_v")
        for position, (s, frames) in enumerate(zip(set_indices, reader.iter_sets(), strict=True)):
            again = reader.read_set(position)
            assert [f.frame_id for f in again] == [f.frame_id for f in frames]
            for written, read in zip(_frames(s), frames, strict=True):
                assert (read.frame_id, read.host_time_ns, read.device_timestamp) == (
                    written.frame_id, written.host_time_ns, written.device_timestamp)
                np.testing.assert_array_equal(read.pixels, written.pixels)
                assert read.pixels.dtype == np.uint16
                numeric = {k: v for k, v in written.metadata.items() if k != "pixel_format"}
                assert dict(read.metadata) == numeric  # float64 holds these exactly; strings are not stored
        assert reader.aperture_for(-1) is None
        for s in (0, 1, 2, 3):
            np.testing.assert_array_equal(reader.aperture_for(s), first_mask)
        for s in (4, 5, 100):
            np.testing.assert_array_equal(reader.aperture_for(s), second_mask)
        results = reader.results()
        assert reader.n_results == 5
    expected = [_result(s) for s in set_indices]
    assert list(results) == list(expected[0])  # column order of the first record
    for key, first in expected[0].items():
        column = [row[key] for row in expected]
        if isinstance(first, np.ndarray):
            np.testing.assert_array_equal(results[key], np.stack(column))  # written values, exact in float64
        else:
            assert results[key].tolist() == column  # lists: a numpy str array would strip the trailing NUL
    assert results["coefficients"].shape == (5, 15)
    assert results["valid"].dtype == np.bool_
    assert results["note"][3] == "ensemble 4 — λ/20\x00" and isinstance(results["note"][3], str)
    assert results["method"][0] == ""


def test_refuses_to_overwrite(tmp_path: Path) -> None:
    path = tmp_path / "existing.h5"
    path.write_text("precious")
    with pytest.raises(FileExistsError, match="existing.h5"):
        _writer(path)
    assert path.read_text() == "precious"
    with _writer(path, overwrite=True) as writer:
        writer.append_set(0, _frames(0))
    with RecordingReader(path) as reader:
        assert reader.n_sets == 1


def test_bad_files_are_input_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such file"):
        RecordingReader(tmp_path / "missing.h5")
    text = tmp_path / "notes.h5"
    text.write_text("not hdf5")
    with pytest.raises(InputError, match=r"notes\.h5.*wavestack recording"):
        RecordingReader(text)
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["data"] = np.arange(3)
    with pytest.raises(InputError, match=r"other\.h5: not a wavestack recording"):
        RecordingReader(other)
    newer = tmp_path / "newer.h5"
    with _writer(newer):
        pass
    with h5py.File(newer, "r+") as f:
        f.attrs["format_version"] = FORMAT_VERSION + 1
    with pytest.raises(InputError, match=rf"newer\.h5: recording format version {FORMAT_VERSION + 1} is newer"):
        RecordingReader(newer)


@pytest.mark.parametrize(("change", "key"), [
    (lambda r: r.pop("rms_nm"), "rms_nm"),
    (lambda r: r.update(extra=1.0), "extra"),
    (lambda r: r.update(coefficients=np.zeros(14)), "coefficients"),
    (lambda r: r.update(set_index="seven"), "set_index"),
    (lambda r: r.update(method=3), "method"),
    (lambda r: r.update(set_index=2.5), "set_index"),  # a float in an int column would be truncated
    (lambda r: r.update(note="lone \ud800 surrogate"), "note"),  # not encodable as UTF-8
])
def test_result_column_mismatch_names_the_key(tmp_path: Path, change: Any, key: str) -> None:
    path = tmp_path / "mismatch.h5"
    with _writer(path) as writer:
        writer.append_result(_result(0))
        bad = _result(1)
        change(bad)
        with pytest.raises(ValueError, match=repr(key)):
            writer.append_result(bad)
        writer.append_result(_result(2))
    with RecordingReader(path) as reader:
        results = reader.results()
    # The rejected record left no partial row: every column holds exactly the two good rows.
    assert all(len(column) == 2 for column in results.values())
    assert results["set_index"].tolist() == [0, 2]


def test_set_and_aperture_validation(tmp_path: Path) -> None:
    with _writer(tmp_path / "v.h5") as writer:
        with pytest.raises(ValueError, match="frames_per_set=3"):
            writer.append_set(0, _frames(0)[:2])
        wrong_shape = [Frame(0, 0, 0, np.zeros((6, 8), np.uint16))] * FPS
        with pytest.raises(ValueError, match=r"expected \(6, 7\)"):
            writer.append_set(0, wrong_shape)
        floats = [Frame(0, 0, 0, np.zeros(SHAPE, np.float32))] * FPS
        with pytest.raises(ValueError, match="castable to uint16"):
            writer.append_set(0, floats)
        writer.append_set(3, _frames(3))
        with pytest.raises(ValueError, match="must exceed the previous 3"):
            writer.append_set(3, _frames(3))
        with pytest.raises(ValueError, match="bool"):
            writer.append_aperture(0, np.ones(SHAPE, np.uint8))
        writer.append_aperture(5, np.ones(SHAPE, bool))
        with pytest.raises(ValueError, match="below the previous"):
            writer.append_aperture(4, np.ones(SHAPE, bool))
    with pytest.raises(ValueError, match="closed"):
        writer.append_set(4, _frames(4))
    template = tmp_path / "template.h5"
    with pytest.raises(ValueError, match="'bad'"):
        _writer(template, result_template={"ok": 1.0, "bad": None})
    assert not template.exists()  # refused before the file was created


def test_crash_safe_once_columns_are_known(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    with _writer(tmp_path / "late.h5") as writer:
        writer.append_set(0, _frames(0))
        assert not writer.crash_safe  # result columns unknown: SWMR cannot start yet
        writer.append_result(_result(0))
        assert writer.crash_safe
    declared = _writer(tmp_path / "early.h5", metadata_keys=("pzt_commanded_v",), result_template=_result(0))
    with declared as writer, caplog.at_level(logging.WARNING):
        assert writer.crash_safe
        writer.append_set(0, _frames(0))
    assert "pzt_readback_v" in caplog.text  # undeclared metadata is logged, not stored
    with RecordingReader(tmp_path / "early.h5") as reader:
        assert reader.metadata_keys == ("pzt_commanded_v",)
        assert reader.n_results == 0 and reader.results()["note"].shape == (0,)


@settings(max_examples=25, deadline=None)
@given(texts=st.lists(st.text(max_size=12), min_size=1, max_size=6),
       values=st.lists(st.floats(allow_nan=False, width=64), min_size=6, max_size=6))
def test_string_and_float_columns_round_trip(texts: list[str], values: list[float]) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "p.h5"
        with _writer(path) as writer:
            for text, value in zip(texts, values):
                writer.append_result({"text": text, "value": value})
        with RecordingReader(path) as reader:
            results = reader.results()
    assert results["text"].tolist() == texts
    assert results["value"].tolist() == values[: len(texts)]


_CRASH_WRITER = textwrap.dedent("""
    import sys
    import numpy as np
    from wavestack.drivers.frames import Frame
    from wavestack.recording import RecordingWriter

    base = np.arange(16 * 16, dtype=np.int64).reshape(16, 16)
    with RecordingWriter(sys.argv[1], config_toml="x = 1", conventions={}, software_version="crash",
                         frame_shape=(16, 16), frame_dtype=np.uint16, frames_per_set=2, chunk_sets=4) as writer:
        committed = 0
        for s in range(200_000):
            if s in (0, 10):
                writer.append_aperture(s, (base % (s + 2)) == 0)
            frames = [Frame(2 * s + j, s, s, ((base + 1000 * s + j) % 65536).astype(np.uint16),
                            {"pzt_commanded_v": s + 0.5 * j}) for j in range(2)]
            writer.append_set(s, frames)
            writer.append_result({"set_index": s, "coefficients": np.arange(5) * 0.5 * s, "label": f"set-{s}"})
            if writer.committed_sets != committed:
                committed = writer.committed_sets
                print(committed, flush=True)
""")


def test_sigkill_keeps_every_committed_set(tmp_path: Path) -> None:
    path = tmp_path / "killed.h5"
    target = 40  # sets committed (10 commits of chunk_sets=4) before the kill
    last_reported = 0
    with subprocess.Popen([sys.executable, "-c", _CRASH_WRITER, str(path)], stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True) as proc:
        assert proc.stdout is not None
        for line in proc.stdout:
            last_reported = int(line)
            if last_reported >= target:
                proc.send_signal(signal.SIGKILL)  # mid-run: the writer is appending the next chunk
                break
        proc.wait()
        stderr = proc.stderr.read() if proc.stderr else ""
    assert proc.returncode == -signal.SIGKILL, f"writer ended on its own ({proc.returncode}): {stderr}"
    assert last_reported >= target

    base = np.arange(16 * 16, dtype=np.int64).reshape(16, 16)
    with RecordingReader(path) as reader:
        assert not reader.closed_cleanly  # the kill left the file flagged open: read through SWMR
        assert reader.n_sets >= last_reported
        assert reader.set_indices.tolist() == list(range(reader.n_sets))
        for s, frames in enumerate(reader.iter_sets()):
            for j, frame in enumerate(frames):
                np.testing.assert_array_equal(frame.pixels, ((base + 1000 * s + j) % 65536).astype(np.uint16))
                assert (frame.frame_id, frame.metadata["pzt_commanded_v"]) == (2 * s + j, s + 0.5 * j)
        np.testing.assert_array_equal(reader.aperture_for(9), (base % 2) == 0)
        np.testing.assert_array_equal(reader.aperture_for(10), (base % 12) == 0)
        results = reader.results()
    # A commit of n sets runs when set n arrives, after the result of set n - 1: n results survive.
    n_results = len(results["set_index"])
    assert n_results >= last_reported
    assert results["set_index"].tolist() == list(range(n_results))
    np.testing.assert_array_equal(results["coefficients"], np.outer(np.arange(n_results), np.arange(5) * 0.5))
    assert results["label"].tolist() == [f"set-{s}" for s in range(n_results)]
