"""``wavestack batch`` end to end, each run in a child process group (killed at teardown): the
results equal ``replay`` of each file, a damaged file is reported and its readable part analysed,
an interrupted campaign resumes without recomputing, and two ``dask worker`` processes against a
``dask scheduler`` on 127.0.0.1 give the same table."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from wavestack.batch import ResultsStore
from wavestack.pipeline import InputError

DASK = Path(sys.executable).with_name("dask")
START_S = 120.0  # a dask worker imports wavestack on its first task: ~10 s on the loaded machine


@pytest.fixture(scope="module")
def expected(campaign, replay_by_cli) -> dict[str, list[dict[str, object]]]:
    """``wavestack replay``'s rows of each recording (computed once, by the command in a child process)."""
    return replay_by_cli([*campaign.station, campaign.masked, campaign.flipped, campaign.truncated])


def _table(out: Path, comparable) -> dict[str, list[dict[str, object]]]:
    rows: dict[str, list[dict[str, object]]] = {}
    for row in ResultsStore(out).read_rows().to_pylist():
        row.pop("aperture_id")  # not in replay's JSON (compared with an in-process replay in test_tasks)
        rows.setdefault(row["recording"], []).append(comparable(row))
    return rows


def _json_lines(text: str) -> list[dict]:
    return [json.loads(line) for line in text.splitlines() if line.startswith("{")]


def test_a_local_campaign_equals_replay_of_each_file_and_reports_damaged_ones(campaign, expected, batch, tmp_path: Path,
                                                                               comparable) -> None:
    flipped, truncated, garbage = campaign.flipped, campaign.truncated, campaign.garbage
    out = tmp_path / "out"
    inputs = [*map(str, campaign.station), str(flipped), str(truncated), str(garbage)]
    done = batch.run(*inputs, "--workers", "2", "--out", str(out), "--json")
    assert done.status == 2, done.stderr  # damaged files: the rest committed, the damage reported
    assert "Traceback" not in done.stderr
    lines = _json_lines(done.stdout)
    summaries = {line["recording"]: line for line in lines if line["type"] == "recording"}
    assert set(summaries) == set(inputs)
    progress = [line for line in lines if line["type"] == "progress"]
    assert progress[-1]["sets_done"] == progress[-1]["sets_total"] > 0
    table = _table(out, comparable)
    for path in campaign.station:
        assert summaries[str(path)]["status"] == "ok"
        assert table[str(path)] == expected[str(path)], path  # identical to wavestack replay
    assert summaries[str(flipped)]["status"] == "damaged" and summaries[str(flipped)]["skipped"] == 1
    assert "CRC-32" in summaries[str(flipped)]["damage"]
    assert table[str(flipped)] == expected[str(flipped)]  # its readable part, as replay gives it
    assert table.get(str(truncated), []) == expected[str(truncated)]
    assert summaries[str(truncated)]["status"] in ("damaged", "skipped") and summaries[str(truncated)]["damage"] + \
        summaries[str(truncated)]["message"]
    assert summaries[str(garbage)]["status"] == "skipped" and "not an HDF5 file" in summaries[str(garbage)]["message"]
    assert str(garbage) in done.stderr and str(flipped) in done.stderr  # one line each on stderr


@pytest.mark.slow
def test_an_interrupted_campaign_resumes_where_it_stopped(campaign, expected, batch, tmp_path: Path,
                                                         comparable) -> None:
    out = tmp_path / "out"
    inputs = [str(campaign.live), str(campaign.masked), str(campaign.later), str(campaign.noisy)]
    child = batch.start(*inputs, "--workers", "1", "--out", str(out), "--json")
    assert child.stdout is not None
    first = None
    for line in child.stdout:  # the first committed recording, then Ctrl-C (the whole group, as a terminal)
        if line.startswith('{"type": "recording"'):
            first = json.loads(line)["recording"]
            os.killpg(child.pid, signal.SIGINT)
            break
    child.communicate(timeout=120)
    assert first is not None and child.returncode != 0
    committed = {p.name: (out / "results" / p.name).stat().st_mtime_ns  # a summary commits its recording
                 for p in (out / "summaries").glob("*.parquet")}
    assert 1 <= len(committed) < len(inputs), committed

    done = batch.run(*inputs, "--workers", "1", "--out", str(out), "--json", "--resume")
    assert done.status == 0, done.stderr
    lines = _json_lines(done.stdout)
    resumed = lines[-1]["resumed_recordings"]
    analysed = [line["recording"] for line in lines if line["type"] == "recording"]
    assert first in resumed and len(resumed) == len(committed) and sorted(resumed + analysed) == sorted(inputs)
    for name, mtime in committed.items():  # nothing recomputed for the finished recordings
        assert (out / "results" / name).stat().st_mtime_ns == mtime
    assert _table(out, comparable) == {p: expected[p] for p in inputs}
    again = batch.run(*inputs, "--workers", "1", "--out", str(out))  # without --resume: refused, nothing lost
    assert again.status == 2 and "--resume" in again.stderr and _table(out, comparable) == {p: expected[p] for p in inputs}

    # A summary commits to its rows (count and SHA-256): a rows file deleted or garbled since is not
    # trusted; --resume analyses those recordings again and the table is whole (it lost rows silently).
    rows_files = sorted((out / "results").glob("*.parquet"))
    rows_files[0].unlink()
    rows_files[1].write_bytes(b"PAR1 not what the summary committed to PAR1")
    assert len(ResultsStore(out).committed()) == len(inputs) - 2
    mended = batch.run(*inputs, "--workers", "1", "--out", str(out), "--json", "--resume")
    assert mended.status == 0, mended.stderr
    lines = _json_lines(mended.stdout)
    assert len([line for line in lines if line["type"] == "recording"]) == 2
    assert len(lines[-1]["resumed_recordings"]) == len(inputs) - 2
    assert _table(out, comparable) == {p: expected[p] for p in inputs}


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.fixture
def cluster(tmp_path: Path) -> Iterator[str]:
    """``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1; killed at teardown."""
    address = f"tcp://127.0.0.1:{_free_port()}"
    env = os.environ | {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    logs, children = [], []
    commands = [[str(DASK), "scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                 "--no-dashboard"],
                *([[str(DASK), "worker", address, "--nthreads", "1", "--no-dashboard"]] * 2)]
    try:
        for n, command in enumerate(commands):
            log = tmp_path / f"dask-{n}.log"
            with log.open("w") as sink:
                children.append(subprocess.Popen(command, stdout=sink, stderr=subprocess.STDOUT, env=env,
                                                 start_new_session=True))
            logs.append(log)
        deadline = time.monotonic() + START_S
        while logs[0].read_text().count("Register worker") < 2:  # both workers joined the scheduler
            assert time.monotonic() < deadline, logs[0].read_text()[-2000:]
            assert all(c.poll() is None for c in children), [log.read_text()[-1000:] for log in logs]
            time.sleep(0.2)
        yield address
    finally:
        for child in children:
            try:
                os.killpg(child.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            child.wait()


@pytest.mark.slow
def test_two_workers_on_a_remote_scheduler_give_the_local_results(campaign, expected, batch, cluster,
                                                                  tmp_path: Path, comparable) -> None:
    out = tmp_path / "remote"
    inputs = [str(campaign.live), str(campaign.masked), str(campaign.noisy)]
    done = batch.run(*inputs, "--scheduler", cluster, "--out", str(out), "--json")
    assert done.status == 0, done.stderr
    assert _table(out, comparable) == {p: expected[p] for p in inputs}


def test_bad_input_is_one_line_before_any_cluster_starts(campaign, tmp_path: Path, capsys) -> None:
    from wavestack.cli import main

    assert main(["batch", str(tmp_path / "missing.h5"), "--out", str(tmp_path / "o")]) == 2
    assert "missing.h5" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exited:
        main(["batch", str(campaign.live), "--workers", "0", "--out", str(tmp_path / "o")])
    assert exited.value.code == 2
    assert "--workers" in capsys.readouterr().err
    file_out = tmp_path / "a-file"
    file_out.write_text("")
    assert main(["batch", str(campaign.live), "--out", str(file_out)]) == 2
    assert "must be a directory" in capsys.readouterr().err
    with pytest.raises(InputError):
        ResultsStore(file_out)
