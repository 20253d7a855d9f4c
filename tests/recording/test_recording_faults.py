"""Fault suite for recordings (issue 13): truncation, bit flips, a damaged superblock, SIGKILL.

The recording is made by the real command (``wavestack run --record`` on the small simulated
station, in a subprocess), and its live results (the JSON lines) are the reference. Each damaged
copy is replayed by ``wavestack replay --json`` in one child process, one file after the other,
each with its own deadline: a replay that hangs (as it did on a recording truncated to 0.1-10 %)
fails the test instead of stalling the suite. Every replay must either reproduce the intact part
exactly and report the rest (exit 2), or fail with one line (exit 2), and always finish.
"""

from __future__ import annotations

import json
import os
import selectors
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import pytest

from wavestack.cli import main
from wavestack.recording import RecordingReader, recorded_config, replay
from wavestack.recording.replay import ReplayedResult

SMALL = Path(__file__).resolve().parents[1] / "configs" / "station-small.toml"
CLI = "import sys; from wavestack.cli import main; sys.exit(main())"
PER_FILE_S = 60.0  # a replay of 6 small sets takes ~2 s; a hang took minutes
#: Replayed coefficients against the live ones, waves: the replay reruns the same float64
#: computation on the same pixels, so it agrees to rounding; 1e-6 is the issue's bound.
ATOL = 1e-6


@dataclass(frozen=True)
class Live:
    path: Path
    results: dict[int, dict]  # station set index -> live JSON result


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Live:
    path = tmp_path_factory.mktemp("live") / "live.h5"
    done = subprocess.run([sys.executable, "-c", CLI, "run", "--config", str(SMALL), "--frames", "6", "--json",
                           "--record", str(path)], capture_output=True, text=True, timeout=180)
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    return Live(path, {r["index"]: r for r in lines if r["type"] == "result" and r["frame_ids"]})


def _replay_in_child(files: list[Path]) -> dict[Path, dict]:
    """``wavestack replay --json`` on each file in one child process, each within ``PER_FILE_S``."""
    driver = textwrap.dedent("""
        import contextlib, io, json, sys
        from wavestack.cli import main
        for name in sys.argv[1:]:
            out, err = io.StringIO(), io.StringIO()
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                status = main(["replay", name, "--json"])
            print(json.dumps({"file": name, "status": status, "out": out.getvalue(), "err": err.getvalue()}),
                  flush=True)
    """)
    outcomes: dict[Path, dict] = {}
    with subprocess.Popen([sys.executable, "-c", driver, *map(str, files)], stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True) as proc, selectors.DefaultSelector() as selector:
        assert proc.stdout is not None
        selector.register(proc.stdout, selectors.EVENT_READ)
        for name in files:
            if not selector.select(timeout=PER_FILE_S + 30 * (name == files[0])):  # the first also imports
                proc.kill()
                pytest.fail(f"replay of {name.name} did not finish within {PER_FILE_S} s (a hang)")
            line = proc.stdout.readline()
            assert line, f"replay child died at {name.name}: {proc.stderr.read() if proc.stderr else ''}"
            outcome = json.loads(line)
            outcomes[Path(outcome["file"])] = outcome
        proc.wait(timeout=30)
    return outcomes


def _copy(source: Path, target: Path, keep: float = 1.0) -> Path:
    data = source.read_bytes()
    target.write_bytes(data[: int(len(data) * keep)])
    return target


def _flip(path: Path, offset: int, mask: int = 0x10) -> None:
    with path.open("r+b") as stream:
        stream.seek(offset)
        byte = stream.read(1)[0]
        stream.seek(offset)
        stream.write(bytes([byte ^ mask]))


def _chunk(path: Path, name: str, row: int) -> tuple[int, int]:
    """(byte offset, size) of the chunk of dataset ``name`` holding ``row``."""
    with h5py.File(path, "r") as f:
        dataset = f[name]
        info = dataset.id.get_chunk_info_by_coord((row - row % dataset.chunks[0],) + (0,) * (dataset.ndim - 1))
    return info.byte_offset, info.size


def _check_outcome(label: str, outcome: dict, live: Live) -> tuple[list[dict], list[dict], dict | None]:
    """The invariants of every replay; returns (results, skipped, summary)."""
    name = Path(outcome["file"]).name
    assert "Traceback" not in outcome["err"], f"{label}: {outcome['err']}"
    lines = [json.loads(line) for line in outcome["out"].splitlines()]
    damaged = any(r.get("damage") for r in lines)
    results = [r for r in lines if r["type"] == "result"]
    skipped = [r for r in lines if r["type"] == "skipped"]
    summary = next((r for r in lines if r["type"] == "summary"), None)
    ours = [line for line in outcome["err"].splitlines() if line.startswith("wavestack replay")]
    if summary is None:  # failed: one line naming the file, exit 2
        assert outcome["status"] == 2 and len(ours) == 1 and name in ours[0], f"{label}: {outcome}"
        return results, skipped, None
    for result in results:  # every replayed set before the first damaged one reproduces the live result exactly
        if result["affected_by_damage"]:  # a set before it was lost, or its recorded row (and live fitter)
            assert damaged, label
            continue
        reference = live.results[result["index"]]
        assert result["valid"] == reference["valid"], label
        if reference["valid"]:
            np.testing.assert_allclose(result["coefficients"], reference["coefficients"], rtol=0, atol=ATOL)
    assert outcome["status"] == (2 if damaged else 0), f"{label}: {outcome}"
    if len(results) < len(live.results) or skipped:
        assert damaged, f"{label}: sets went missing without a damage report: {summary}"
    return results, skipped, summary


@pytest.mark.slow
def test_damaged_recordings_replay_their_intact_part_or_fail_in_one_line(live: Live, tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture) -> None:
    cases: dict[str, Path] = {}
    for keep in (0.001, 0.01, 0.1, 0.5, 0.9, 0.99):
        cases[f"truncated {keep:.1%}"] = _copy(live.path, tmp_path / f"cut-{keep}.h5", keep)
    flipped = cases["pixel flip"] = _copy(live.path, tmp_path / "pixel-flip.h5")
    offset, size = _chunk(flipped, "sets/pixels", 2)
    _flip(flipped, offset + size // 2)
    zeroed = cases["pixel chunk zeroed"] = _copy(live.path, tmp_path / "pixel-zeroed.h5")
    offset, size = _chunk(zeroed, "sets/pixels", 3)
    with zeroed.open("r+b") as stream:  # fletcher32 would accept an all-zero chunk: the per-set CRC-32 does not
        stream.seek(offset)
        stream.write(bytes(size))
    result_flip = cases["result flip"] = _copy(live.path, tmp_path / "result-flip.h5")
    offset, _ = _chunk(result_flip, "results/coefficients", 1)
    with h5py.File(result_flip, "r") as f:
        row_bytes = f["results/coefficients"].dtype.itemsize * f["results/coefficients"].shape[1]
    _flip(result_flip, offset + row_bytes + 3)  # inside row 1
    config_flip = cases["config flip"] = _copy(live.path, tmp_path / "config-flip.h5")
    _flip(config_flip, config_flip.read_bytes().index(b"[processing]") + 3)
    heap_flip = cases["conventions flip"] = _copy(live.path, tmp_path / "conventions-flip.h5")
    _flip(heap_flip, heap_flip.read_bytes().index(b"waves of wavefront") + 2)
    superblock = cases["superblock"] = _copy(live.path, tmp_path / "superblock.h5")
    _flip(superblock, 20)

    outcomes = _replay_in_child(list(cases.values()))
    seen = {label: _check_outcome(label, outcomes[path], live) for label, path in cases.items()}

    for label in ("truncated 0.1%", "config flip", "conventions flip", "superblock"):
        assert seen[label][2] is None, f"{label} should fail in one line: {outcomes[cases[label]]}"
    results, skipped, summary = seen["pixel flip"]
    assert [s["position"] for s in skipped] == [2] and len(results) == len(live.results) - 1
    assert "CRC-32" in summary["damage"][0]
    results, skipped, summary = seen["pixel chunk zeroed"]
    assert [s["position"] for s in skipped] == [3] and "CRC-32" in summary["damage"][0]
    results, skipped, summary = seen["result flip"]  # one chunk holds the 6 rows: all are lost, no set
    assert len(results) == len(live.results) and not skipped and summary["compared"] < len(live.results)
    assert any(d.startswith("results") for d in summary["damage"])
    assert main(["replay", str(flipped)]) == 2  # the text view says the same: set 2 skipped, one line on stderr
    out, err = capsys.readouterr()
    assert "(recorded set 2): not replayed, damaged" in out and "1 damaged sets not replayed" in out
    assert [line for line in err.splitlines() if line.startswith("wavestack replay")] == [
        f"wavestack replay: {flipped}: damaged recording, 1 sets not replayed: sets 2: fails its CRC-32 (changed or "
        "zeroed bytes)"]
    for label in ("truncated 90.0%", "truncated 99.0%"):
        results, skipped, summary = seen[label]
        assert summary is not None and summary["damage"], label  # the cut is reported, whatever survived


@pytest.mark.slow
def test_sigkill_during_wavestack_run_record_replays_up_to_the_last_commit(tmp_path: Path) -> None:
    path = tmp_path / "killed.h5"
    live: dict[int, dict] = {}
    target = 9  # more than chunk_sets (8): at least one commit happened by the count rule alone
    with subprocess.Popen([sys.executable, "-c", CLI, "run", "--config", str(SMALL), "--json", "--record",
                           str(path)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True) as proc:
        assert proc.stdout is not None
        deadline = time.monotonic() + 180
        for line in proc.stdout:
            result = json.loads(line)
            if result["type"] == "result" and result["frame_ids"]:
                live[result["index"]] = result
            if len(live) >= target or time.monotonic() > deadline:
                os.kill(proc.pid, signal.SIGKILL)  # the recorder has appended (and maybe committed) these sets
                break
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL and len(live) >= target

    with RecordingReader(path) as reader:
        assert not reader.closed_cleanly and not reader.damage
        # After each result at most chunk_sets - 1 = 7 sets are uncommitted (the writer's loss window).
        assert reader.n_sets >= len(live) - 7
        replayed = list(replay(reader, recorded_config(reader, path), same_settings=True))
    assert all(isinstance(r, ReplayedResult) for r in replayed)
    assert [r.index for r in replayed] == sorted(live)[: len(replayed)]
    for again in replayed:
        reference = live[again.index]
        if reference["valid"]:
            np.testing.assert_allclose(again.processed.coefficients_waves, reference["coefficients"], rtol=0,
                                       atol=ATOL)
