"""HDF5 files are read in a child process: a file that hangs or crashes the library is refused."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from wavestack.pipeline.formats import InputError, read_datx
from wavestack.pipeline.formats.hdf5_guard import read_guarded

# A .datx found by the fuzz tests (a seed file with five bytes changed): reading its 'Unit'
# attribute (a variable-length string whose global-heap entry is damaged) never returns in HDF5 1.14.
HANGS = Path(__file__).with_name("hdf5-hangs-libhdf5.datx")


@pytest.mark.timeout(120)
def test_a_file_that_hangs_the_hdf5_library_is_refused_after_the_deadline() -> None:
    started = time.monotonic()
    try:
        read_datx(HANGS, timeout_s=3.0)
    except InputError as error:  # on this HDF5: "did not finish within 3 s"; another may say why
        assert str(HANGS) in str(error)
    assert time.monotonic() - started < 60  # the deadline, not the library, ended the read


def _value(path: Path) -> tuple[str, int]:
    return (path.name, 42)


def _crash(path: Path) -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def _hang(path: Path) -> None:
    while True:
        time.sleep(1)


def _typed(path: Path) -> None:
    raise InputError(f"{path}: no surface")


def _bug(path: Path) -> None:
    raise KeyError("internal")


def test_the_child_returns_the_readers_value(tmp_path: Path) -> None:
    assert read_guarded(_value, tmp_path / "x.h5") == ("x.h5", 42)


@pytest.mark.parametrize("reader, fragment", [
    (_crash, "crashed"), (_typed, "no surface"), (_bug, "damaged HDF5 file: KeyError"),
])
def test_every_failure_of_the_child_is_an_input_error_naming_the_file(tmp_path: Path, reader, fragment) -> None:
    with pytest.raises(InputError, match=fragment) as raised:
        read_guarded(reader, tmp_path / "x.h5")
    assert str(tmp_path / "x.h5") in str(raised.value)


def test_a_child_past_its_deadline_is_killed(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="did not finish within 0.5 s"):
        read_guarded(_hang, tmp_path / "x.h5", timeout_s=0.5)
