"""Malformed recordings give one typed error naming the file; damaged bytes never escape as anything else.

Also: the recording path pre-flight (``check_recording_path``), the writer's commit rule, and
version 1 recordings (no checksums) still reading.
"""

from __future__ import annotations

import doctest
import importlib
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fuzz import fuzz_settings
from wavestack.cli import main
from wavestack.drivers.frames import Frame
from wavestack.pipeline import InputError
from wavestack.recording import RecordingDamaged, RecordingReader, RecordingWriter, check_recording_path
from wavestack.pipeline.formats.hdf5_open import lookup3

SHAPE = (8, 9)
FPS = 2


def _frames(s: int) -> list[Frame]:
    return [Frame(2 * s + j, s, s, np.full(SHAPE, 100 * s + j, np.uint16), {"pzt_commanded_v": s + 0.5 * j})
            for j in range(FPS)]


def _record(path: Path, n_sets: int = 5, **kwargs: object) -> Path:
    with RecordingWriter(path, config_toml="x = 1", conventions={"ordering": "noll", "modes": 5},
                         software_version="t", frame_shape=SHAPE, frame_dtype=np.uint16, frames_per_set=FPS,
                         **kwargs) as writer:
        for s in range(n_sets):
            if s == 0:
                writer.append_aperture(0, np.ones(SHAPE, bool))
            writer.append_set(s, _frames(s))
            writer.append_result({"index": s, "valid": True, "coefficients": np.arange(3) * s, "fitter": "qr"})
    return path


def _edit(change: Callable[[h5py.File], None]) -> Callable[[Path], Path]:
    def make(path: Path) -> Path:
        _record(path)
        with h5py.File(path, "r+") as f:
            change(f)
        return path
    return make


def _replace(name: str, data: object) -> Callable[[h5py.File], None]:
    def change(f: h5py.File) -> None:
        del f[name]
        f[name] = data
    return change


def _write(content: bytes) -> Callable[[Path], Path]:
    def make(path: Path) -> Path:
        path.write_bytes(content)
        return path
    return make


MALFORMED: dict[str, tuple[Callable[[Path], Path], str]] = {
    "missing file": (lambda p: p, "no such file"),
    "directory": (lambda p: (p.mkdir(), p)[1], "is a directory"),
    "empty file": (_write(b""), "empty file"),
    "not HDF5": (_write(b"index,coefficients\n0,1.5\n"), "not an HDF5 file"),
    "HDF5 signature only": (_write(b"\x89HDF\r\n\x1a\n"), "superblock"),
    "other HDF5": (lambda p: (h5py.File(p, "w").close(), p)[1], "not a wavestack recording"),
    "no pixels": (_edit(lambda f: f.__delitem__("sets/pixels")), "/sets/pixels"),
    "pixels 3-D": (_edit(_replace("sets/pixels", np.zeros((5, 8, 9), np.uint16))), "/sets/pixels"),
    "string set_index": (_edit(_replace("sets/set_index", np.array([b"a"] * 5))), "/sets/set_index"),
    "frame ids of 3 per set": (_edit(_replace("sets/frame_id", np.zeros((5, 3), np.int64))), "/sets/frame_id"),
    "no config": (_edit(lambda f: f.attrs.__delitem__("config_toml")), "config_toml"),
    "version as text": (_edit(lambda f: f.attrs.__setitem__("format_version", "two")), "format_version"),
    "version 0": (_edit(lambda f: f.attrs.__setitem__("format_version", 0)), "format_version"),
    "version 99": (_edit(lambda f: f.attrs.__setitem__("format_version", 99)), "newer than this wavestack"),
    "no committed counts": (_edit(lambda f: f.__delitem__("committed_counts")), "committed_counts"),
    "mask of other shape": (_edit(_replace("apertures/mask", np.ones((1, 4, 4), bool))), "/apertures/mask"),
    "text result column": (_edit(_replace("results/fitter", np.array([b"qr"] * 5))), "'fitter'"),
    "no results group": (_edit(lambda f: f.__delitem__("results")), "/results"),
    "no integrity group": (_edit(lambda f: f.__delitem__("integrity")), "integrity"),
    "conventions edited": (_edit(lambda f: f["conventions"].attrs.__setitem__("modes", 6)), "header_crc32"),
}


@pytest.mark.parametrize("case", list(MALFORMED))
def test_a_malformed_recording_is_one_input_error_naming_the_file(case: str, tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture) -> None:
    make, expected = MALFORMED[case]
    path = make(tmp_path / "bad.h5")
    with pytest.raises(InputError, match=expected) as raised:
        RecordingReader(path)
    assert str(path) in str(raised.value) and "\n" not in str(raised.value)
    assert main(["replay", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0], err


@pytest.fixture(scope="module")
def recording_bytes(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    return _record(tmp_path_factory.mktemp("fuzz") / "r.h5").read_bytes()


def _read_everything(path: Path) -> None:
    """Open and read every part; only InputError (RecordingDamaged is one) may come out."""
    try:
        with RecordingReader(path) as reader:
            for i in range(reader.n_sets):
                try:
                    reader.read_set(i)
                except RecordingDamaged:
                    pass
            reader.results()
            try:
                reader.aperture_for(0)
            except RecordingDamaged:
                pass
    except InputError:
        pass


@fuzz_settings(300)
@given(data=st.data())
def test_any_truncation_or_byte_change_is_read_or_refused_cleanly(recording_bytes: bytes, data: st.DataObject) -> None:
    content = bytearray(recording_bytes[: data.draw(st.integers(0, len(recording_bytes)), label="keep")])
    for _ in range(data.draw(st.integers(0, 3), label="flips")):
        if content:
            position = data.draw(st.integers(0, len(content) - 1), label="at")
            content[position] ^= data.draw(st.integers(1, 255), label="mask")
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "fuzzed.h5"
        path.write_bytes(bytes(content))
        _read_everything(path)


@fuzz_settings(300)
@given(content=st.binary(max_size=600), signed=st.booleans())
def test_arbitrary_bytes_are_refused_cleanly(content: bytes, signed: bool) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "noise.h5"
        path.write_bytes((b"\x89HDF\r\n\x1a\n" if signed else b"") + content)
        _read_everything(path)


def test_a_flipped_byte_in_a_set_or_row_is_reported_not_replayed(tmp_path: Path) -> None:
    path = _record(tmp_path / "r.h5")
    with h5py.File(path, "r") as f:
        info = f["sets/pixels"].id.get_chunk_info_by_coord((3, 0, 0, 0))
    data = bytearray(path.read_bytes())
    data[info.byte_offset + 5] ^= 0x01
    path.write_bytes(bytes(data))
    with RecordingReader(path) as reader:
        assert reader.n_sets == 5 and not reader.damage
        for i in (0, 1, 2, 4):
            assert reader.read_set(i)[0].pixels[0, 0] == 100 * i
        with pytest.raises(RecordingDamaged, match="recorded set 3"):
            reader.read_set(3)
        assert [str(d) for d in reader.damage] == ["sets 3: fails its CRC-32 (changed or zeroed bytes)"]


def test_a_version_1_recording_without_checksums_still_reads(tmp_path: Path) -> None:
    path = _record(tmp_path / "v1.h5")
    with h5py.File(path, "r+") as f:  # what version 1 wrote: no integrity group, no header CRC
        del f["integrity"]
        del f.attrs["header_crc32"]
        f.attrs["format_version"] = 1
    with RecordingReader(path) as reader:
        assert reader.format_version == 1 and reader.n_sets == 5 and reader.n_results == 5
        assert reader.read_set(4)[1].pixels[0, 0] == 401
        assert any("no checksums" in note for note in reader.notes)


def test_the_superblock_checksum_is_hdf5s_lookup3(tmp_path: Path) -> None:
    head = _record(tmp_path / "r.h5").read_bytes()[:48]
    assert lookup3(head[:44]) == int.from_bytes(head[44:48], "little")


def test_the_writer_commits_after_a_result_once_the_interval_has_passed(tmp_path: Path) -> None:
    with RecordingWriter(tmp_path / "c.h5", config_toml="", conventions={}, software_version="t",
                         frame_shape=SHAPE, frame_dtype=np.uint16, frames_per_set=FPS, chunk_sets=1000,
                         commit_interval_s=0.05) as writer:
        writer.append_set(0, _frames(0))
        writer.append_result({"index": 0})
        deadline = time.monotonic() + 0.05
        while time.monotonic() < deadline:  # wait out the interval (a poll, no timing assertion)
            time.sleep(0.01)
        writer.append_set(1, _frames(1))
        writer.append_result({"index": 1})
        assert writer.committed_sets == 2


def test_check_recording_path(tmp_path: Path) -> None:
    assert check_recording_path(tmp_path / "new.h5") == tmp_path / "new.h5"
    for path, expected in [(tmp_path, "is a directory"), (tmp_path / "missing" / "r.h5", "does not exist"),
                           (Path(os.devnull), "not a regular file")]:
        with pytest.raises(InputError, match=expected) as raised:
            check_recording_path(path)
        assert str(path) in str(raised.value)
    existing = tmp_path / "old.h5"
    existing.write_bytes(b"precious")
    with pytest.raises(InputError, match="already exists"):
        check_recording_path(existing)
    assert check_recording_path(existing, overwrite=True) == existing


@pytest.mark.parametrize("name", ["wavestack.pipeline.formats.hdf5_open", "wavestack.recording.paths"])
def test_examples_run_and_match(name: str) -> None:
    module = importlib.import_module(name)
    tests = [test for test in doctest.DocTestFinder(exclude_empty=True).find(module, name) if test.examples]
    assert tests, f"{name} has no Examples section any more"
    runner = doctest.DocTestRunner()
    for test in tests:
        runner.run(test)
    outcome = runner.summarize(verbose=False)
    assert outcome.failed == 0 and outcome.attempted > 0
