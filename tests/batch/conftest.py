"""Recordings for the batch tests, made once per session, and a runner for ``wavestack batch``.

One recording is made by the real command (``wavestack run --record`` on the small simulated
station); the others are written from its sets with the recording writer (a few seconds instead of
~10 s each): later sets only, pixels with noise, and one whose optic is masked half-way, so that
its aperture changes (the case a large recording is divided at).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import signal
import subprocess
import sys
import textwrap
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import pytest

from wavestack.recording import FRAME_METADATA, RecordingReader, RecordingWriter, recorded_config, replay
from wavestack.recording.replay import ReplayedResult

SMALL = Path(__file__).resolve().parents[1] / "configs" / "station-small.toml"
CLI = "import sys; from wavestack.cli import main; sys.exit(main())"
RUN_TIMEOUT_S = 240.0  # a batch of a few small recordings takes ~10-30 s on the loaded 2-core machine


@dataclass(frozen=True)
class Campaign:
    """The session's recordings: ``live`` (made by wavestack run), ``later``, ``noisy``, ``masked``."""

    root: Path
    live: Path
    later: Path
    noisy: Path
    masked: Path
    flipped: Path
    truncated: Path
    garbage: Path

    @property
    def station(self) -> list[Path]:
        return [self.live, self.later, self.noisy]


def _derive(source: Path, target: Path, sets: Sequence[tuple[int, object]], apertures: dict[int, np.ndarray]) -> Path:
    """A recording of ``sets`` ((position in source, pixel transform)), recorded apertures ``apertures``."""
    with RecordingReader(source) as reader:
        config = recorded_config(reader, source)
        template = {k: (v[0] if len(v) else v) for k, v in reader.results().items()}
        writer = RecordingWriter(target, config_toml=reader.config_toml, conventions=reader.conventions,
                                 software_version=reader.software_version, frame_shape=reader.frame_shape,
                                 frame_dtype=reader.frame_dtype, frames_per_set=config.processing.frames_per_set,
                                 metadata_keys=FRAME_METADATA, result_template=template)
        with writer:
            for index, (position, transform) in enumerate(sets):
                frames = [dataclasses.replace(f, pixels=transform(f.pixels)) for f in reader.read_set(position)]
                frames = [dataclasses.replace(f, frame_id=index * len(frames) + j) for j, f in enumerate(frames)]
                writer.append_set(index, frames)
                if index in apertures:
                    writer.append_aperture(index, apertures[index])
    return target


def _masked(pixels: np.ndarray) -> np.ndarray:
    out = pixels.copy()
    out[: out.shape[0] // 3, :] = 0  # the top third of the optic covered: a new aperture
    return out


def _noisy(seed: int):
    def transform(pixels: np.ndarray) -> np.ndarray:
        noise = np.random.default_rng(seed).normal(0.0, 4.0, pixels.shape)
        return np.clip(pixels + noise, 0, 4095).astype(pixels.dtype)
    return transform


def _adoptions(path: Path) -> dict[int, np.ndarray]:
    """Set index -> mask of each aperture the replay adopts (what the live run would have recorded)."""
    with RecordingReader(path) as reader:
        return {r.index: r.processed.new_aperture_mask for r in replay(reader, recorded_config(reader, path),
                                                                        same_settings=True)
                if getattr(r.processed, "new_aperture_mask", None) is not None}


@pytest.fixture(scope="session")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Campaign:
    root = tmp_path_factory.mktemp("campaign")
    live = root / "live.h5"
    done = subprocess.run([sys.executable, "-c", CLI, "run", "--config", str(SMALL), "--frames", "6",
                           "--record", str(live)], capture_output=True, text=True, timeout=RUN_TIMEOUT_S)
    assert done.returncode == 0, done.stderr
    same = lambda pixels: pixels  # noqa: E731
    later = _derive(live, root / "later.h5", [(p, same) for p in range(1, 6)], {})
    noisy = _derive(live, root / "noisy.h5", [(p, _noisy(p)) for p in range(6)], {})
    plan = [*((p, same) for p in range(6)), *((p, _masked) for p in range(6))]
    draft = _derive(live, root / "masked-draft.h5", plan, {})
    masked = _derive(live, root / "masked.h5", plan, _adoptions(draft))
    draft.unlink()
    return Campaign(root, live, later, noisy, masked, *_damaged_copies(live, root))


def _damaged_copies(live: Path, root: Path) -> tuple[Path, Path, Path]:
    """``live`` with one byte of set 2's pixels flipped, ``live`` cut at 60 %, and a file that is not HDF5."""
    flipped = root / "flipped.h5"
    flipped.write_bytes(live.read_bytes())
    with h5py.File(flipped, "r") as f:
        info = f["sets/pixels"].id.get_chunk_info_by_coord((2, 0, 0, 0))
    with flipped.open("r+b") as stream:
        stream.seek(info.byte_offset + info.size // 2)
        byte = stream.read(1)[0]
        stream.seek(info.byte_offset + info.size // 2)
        stream.write(bytes([byte ^ 0x10]))
    truncated = root / "truncated.h5"
    data = live.read_bytes()
    truncated.write_bytes(data[: int(len(data) * 0.6)])
    garbage = root / "garbage.h5"
    garbage.write_bytes(b"\x00 not a recording " * 64)
    return flipped, truncated, garbage


#: Fields of a replayed result a batch row must reproduce exactly (ReplayedResult.to_json's).
COMPARED = ("index", "frame_ids", "valid", "reason", "coefficients", "fitter", "fitter_fallback", "unwrap_path",
            "residual_rms", "residual_pv", "difference_rms", "residual_pv_difference", "affected_by_damage")


def _replayed_rows(path: Path) -> list[dict[str, object]]:
    """``wavestack replay``'s results of ``path`` (recorded settings) as comparable dicts."""
    with RecordingReader(path) as reader:
        items = [r for r in replay(reader, recorded_config(reader, path), same_settings=True)
                 if isinstance(r, ReplayedResult)]
    return [_comparable(r.to_json() | {"aperture_id": -1 if r.processed.choice is None
                                      else r.processed.choice.aperture_id}) for r in items]


def _comparable(values: dict[str, object]) -> dict[str, object]:
    """The compared fields, None and NaN alike (the table stores NaN for 'not compared'), tuples as lists."""
    out: dict[str, object] = {}
    for key in (*COMPARED, *(("aperture_id",) if "aperture_id" in values else ())):
        value = values.get(key)
        value = list(value) if isinstance(value, (tuple, list)) else value
        out[key] = None if value is None or (isinstance(value, float) and math.isnan(value)) else value
        if key in ("reason", "fitter", "unwrap_path") and out[key] is None:  # the table stores ""
            out[key] = ""
    return out


_REPLAY_DRIVER = textwrap.dedent("""
    import contextlib, io, json, sys
    from wavestack.cli import main
    flags = json.loads(sys.argv[1])
    for name in sys.argv[2:]:
        out = io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
            main(["replay", name, "--json", *flags])
        print(json.dumps({"file": name, "out": out.getvalue()}), flush=True)
""")


def _replay_by_cli(paths: Sequence[Path], *flags: str) -> dict[str, list[dict[str, object]]]:
    """``wavestack replay --json`` of each file, in one child process (the command's one BLAS thread,
    as the batch's workers have), as comparable rows: the reference the batch must equal."""
    done = subprocess.run([sys.executable, "-c", _REPLAY_DRIVER, json.dumps(flags), *map(str, paths)],
                          capture_output=True, text=True,
                          timeout=RUN_TIMEOUT_S)
    assert done.returncode == 0, done.stderr
    found = {}
    for line in done.stdout.splitlines():
        outcome = json.loads(line)
        results = [json.loads(r) for r in outcome["out"].splitlines()]
        found[outcome["file"]] = [_comparable(r) for r in results if r["type"] == "result"]
    return found


@pytest.fixture(scope="session")
def replay_by_cli():
    """``wavestack replay --json`` of files, as comparable rows (a function)."""
    return _replay_by_cli


@pytest.fixture(scope="session")
def replayed_rows():
    """``wavestack replay``'s rows of a recording, comparable with a batch table's (a function)."""
    return _replayed_rows


@pytest.fixture(scope="session")
def comparable():
    """The compared fields of a row or a replayed result's JSON (a function)."""
    return _comparable


@dataclass(frozen=True)
class Finished:
    status: int
    stdout: str
    stderr: str


class BatchRunner:
    """Runs ``wavestack batch`` in a child process of its own process group; kills the group at
    teardown, so no Dask process outlives the test."""

    def __init__(self) -> None:
        self.children: list[subprocess.Popen[str]] = []

    def start(self, *args: str) -> subprocess.Popen[str]:
        child = subprocess.Popen([sys.executable, "-c", CLI, "batch", *args], stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True, start_new_session=True)
        self.children.append(child)
        return child

    def run(self, *args: str) -> Finished:
        child = self.start(*args)
        out, err = child.communicate(timeout=RUN_TIMEOUT_S)
        return Finished(child.returncode, out, err)

    def close(self) -> None:
        for child in self.children:
            try:
                os.killpg(child.pid, signal.SIGKILL)  # the child and the cluster it spawned
            except ProcessLookupError:
                pass
            child.communicate()


@pytest.fixture
def batch() -> Iterator[BatchRunner]:
    runner = BatchRunner()
    try:
        yield runner
    finally:
        runner.close()
