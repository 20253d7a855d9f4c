"""Hostile configuration files: a FIFO, /dev/zero, nesting that exhausts the parser; and a job name taken.

Each is one line and exit status 2 (bad input), at once; none reads forever or ends with a traceback.
"""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from wavestack.cli import EXIT_BAD_INPUT, main
from wavestack.drivers.plc import JobFile, JobRefused, write_job_file


def _run(args: list[str], capsys) -> tuple[int, str, float]:
    start = time.monotonic()
    status = main(args)
    return status, capsys.readouterr().err, time.monotonic() - start


def test_dev_zero_as_the_configuration_is_refused_at_once(capsys) -> None:
    status, err, seconds = _run(["run", "--config", "/dev/zero", "--duration", "1"], capsys)
    assert status == EXIT_BAD_INPUT and err.count("\n") == 1 and "/dev/zero" in err and "not a regular file" in err
    assert seconds < 10.0  # it was read forever


def test_a_fifo_as_the_configuration_is_refused_without_waiting(tmp_path: Path, capsys) -> None:
    fifo = tmp_path / "station.toml"
    os.mkfifo(fifo)
    writer = threading.Timer(10.0, _unblock, args=(fifo,))  # the old reader waited for a writer: one comes at 10 s
    writer.start()
    try:
        status, err, seconds = _run(["run", "--config", str(fifo), "--duration", "1"], capsys)
    finally:
        writer.cancel()
        writer.join()
    assert status == EXIT_BAD_INPUT and err.count("\n") == 1 and "not a regular file" in err
    assert seconds < 5.0


def _unblock(path: Path) -> None:
    try:
        os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
    except OSError:  # nobody waits on it: nothing to unblock
        pass


@pytest.mark.parametrize("nesting", ["a = " + "[" * 5000 + "]" * 5000, "a = " + "{b = " * 5000 + "1" + "}" * 5000])
def test_deeply_nested_toml_is_bad_input_not_a_crash(tmp_path: Path, capsys, nesting: str) -> None:
    config = tmp_path / "nested.toml"
    config.write_text(nesting + "\n")
    status, err, _ = _run(["run", "--config", str(config), "--duration", "1"], capsys)
    assert status == EXIT_BAD_INPUT and err.count("\n") == 1 and "nested too deeply" in err


def test_a_job_name_taken_in_the_meantime_is_never_overwritten(tmp_path: Path) -> None:
    # a name that exists() does not see (a dangling symlink: another host's job being put in place) stays
    taken = tmp_path / "job-00007.wsjob"
    taken.symlink_to(tmp_path / "elsewhere" / "job-00007.wsjob")
    job = JobFile(7, np.zeros(2), np.zeros(2), np.ones(2), np.full(2, 10.0), 0.1, {"kind": "gaussian"}, {})
    with pytest.raises(JobRefused, match="refusing to overwrite job-00007.wsjob"):
        write_job_file(tmp_path, job)
    assert taken.is_symlink()
    assert [p.name for p in tmp_path.iterdir()] == ["job-00007.wsjob"]  # no temporary file left behind
