"""Benchmark of ``wavestack batch``: sets per second on 1 and 2 local workers, against the station's
processing stages alone in one process.

Run:  .venv/bin/python benchmarks/bench_batch.py [--recordings 20] [--sets 12] [--cache DIR] [--batched-fits]

The campaign: one recording made by ``wavestack run --record`` on the small simulated station
(256 x 256, 5-frame sets), then ``--recordings`` recordings written from its sets with seeded
noise added to the pixels (each its own file, hash and fitter builds), generated once into the
cache directory. Each run starts a local cluster, imports wavestack on every worker (``client.run``)
and only then times ``run_campaign``: cluster start-up and imports are paid once per campaign, not
per set. The campaign runs on 1, then 2, then 1 worker again; the 1-worker time is the mean of the
two (the order and the drift of a shared machine cancel to first order). The baseline is ``build_processor(config).process`` on the same
sets, read into memory beforehand, one fresh processor per recording (as a replay builds one), in
this process. Printed with ``uptime``'s load: on a shared machine, the ratios of one run are what
survives, not the absolute rates.
"""

from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"  # as wavestack's CLI: before numpy loads; the workers inherit it

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import logging  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from wavestack.batch import ResultsStore, campaign_client, prepare_campaign, run_campaign  # noqa: E402
from wavestack.config import parse_station_config  # noqa: E402
from wavestack.recording import FRAME_METADATA, RecordingReader, RecordingWriter  # noqa: E402
from wavestack.station import build_processor  # noqa: E402

SMALL = Path(__file__).resolve().parents[1] / "tests" / "configs" / "station-small.toml"
CLI = "import sys; from wavestack.cli import main; sys.exit(main())"


def make_campaign(cache: Path, recordings: int, sets: int) -> list[Path]:
    """The campaign's files (made once; kept in ``cache``)."""
    paths = [cache / f"rec-{n:03d}.h5" for n in range(recordings)]
    if all(p.exists() for p in paths):
        return paths
    cache.mkdir(parents=True, exist_ok=True)
    base = cache / "base.h5"
    base.unlink(missing_ok=True)
    subprocess.run([sys.executable, "-c", CLI, "run", "--config", str(SMALL), "--frames", str(sets), "--record",
                    str(base)], check=True, capture_output=True, timeout=600)
    with RecordingReader(base) as reader:
        originals = [reader.read_set(i) for i in range(reader.n_sets)]
        header = dict(config_toml=reader.config_toml, conventions=reader.conventions,
                      software_version=reader.software_version, frame_shape=reader.frame_shape,
                      frame_dtype=reader.frame_dtype, frames_per_set=len(originals[0]),
                      metadata_keys=FRAME_METADATA, result_template={k: v[0] for k, v in reader.results().items()})
    for n, path in enumerate(paths):
        rng = np.random.default_rng(n)
        with RecordingWriter(path, overwrite=True, **header) as writer:
            for index, frames in enumerate(originals):
                noisy = [dataclasses.replace(f, pixels=np.clip(f.pixels + rng.normal(0, 4.0, f.pixels.shape), 0,
                                                               4095).astype(f.pixels.dtype)) for f in frames]
                writer.append_set(index, noisy)
    return paths


@dataclasses.dataclass(frozen=True)
class CpuUse:
    """CPU seconds (user + system) spent during a campaign, by process (and the client's threads).

    ``client_main``: the thread running ``run_campaign`` (receiving results, writing Parquet);
    ``client_other``: the client process's other threads (the local scheduler's event loop, the
    client's communication); ``workers``: each worker process; ``nannies``: their nanny processes.
    """

    client_main: float
    client_other: float
    workers: tuple[float, ...]
    nannies: float
    busy: tuple[float, ...]  # fraction of the wall time each worker spent in tasks (task stream)


def _cpu_by_process() -> tuple[dict[int, float], dict[int, float]]:
    """(thread id -> CPU s of this process's threads, pid -> CPU s of every descendant process)."""
    import psutil

    me = psutil.Process()
    threads = {t.id: t.user_time + t.system_time for t in me.threads()}
    children = {}
    for child in me.children(recursive=True):
        try:
            times = child.cpu_times()
            children[child.pid] = times.user + times.system
        except psutil.NoSuchProcess:
            continue
    return threads, children


def _worker_pids(client: object) -> set[int]:
    return set(client.run(os.getpid).values())  # type: ignore[attr-defined]


def batch_rate(paths: list[Path], workers: int, out: Path,
               batched_fits: bool = False) -> tuple[float, int, list, CpuUse]:
    """(seconds, sets, summaries, CPU use) of one campaign on a fresh local cluster of ``workers``."""
    import threading

    shutil.rmtree(out, ignore_errors=True)
    store = ResultsStore(out)
    campaign = prepare_campaign([str(p) for p in paths], store, batched_fits=batched_fits)
    with campaign_client(None, workers) as client:
        client.run(__import__, "wavestack.batch.task")  # imports paid before the clock starts
        worker_pids = _worker_pids(client)
        threads_before, children_before = _cpu_by_process()
        tick = time.perf_counter()
        with _task_stream(client) as stream:
            report = run_campaign(campaign, store, client)
        seconds = time.perf_counter() - tick
        threads_after, children_after = _cpu_by_process()
    main = threading.get_native_id()
    spent = {t: v - threads_before.get(t, 0.0) for t, v in threads_after.items()}
    children = {p: v - children_before.get(p, 0.0) for p, v in children_after.items()}
    busy: dict[str, float] = {}
    for task in stream.data:
        for span in task.get("startstops", ()):
            if span.get("action") == "compute":
                busy[task["worker"]] = busy.get(task["worker"], 0.0) + span["stop"] - span["start"]
    use = CpuUse(spent.get(main, 0.0), sum(v for t, v in spent.items() if t != main),
                 tuple(sorted(v for p, v in children.items() if p in worker_pids)),
                 sum(v for p, v in children.items() if p not in worker_pids),
                 tuple(sorted(b / seconds for b in busy.values())))
    return seconds, sum(s.results + s.skipped for s in report.analysed), list(report.analysed), use


def _task_stream(client: object):
    from distributed import get_task_stream

    return get_task_stream(client)


def stages_alone(paths: list[Path]) -> tuple[float, int]:
    """(seconds, sets) of the processing stages alone, one processor per recording, sets in memory."""
    seconds, count = 0.0, 0
    for path in paths:
        with RecordingReader(path) as reader:
            config = parse_station_config(reader.config_toml, source=str(path))
            sets = [[f.pixels for f in reader.read_set(i)] for i in range(reader.n_sets)]
        tick = time.perf_counter()
        processor = build_processor(config)  # every fitter built at once, as a replay builds them
        for frames in sets:
            processor.process(frames)
        seconds += time.perf_counter() - tick
        count += len(sets)
    return seconds, count


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--recordings", type=int, default=20)
    parser.add_argument("--sets", type=int, default=12, help="sets per recording")
    parser.add_argument("--batched-fits", action="store_true", help="fit the maps sharing a fitter in batches")
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "wavestack-bench-batch")
    args = parser.parse_args()
    logging.getLogger("distributed").setLevel(logging.ERROR)
    paths = make_campaign(args.cache, args.recordings, args.sets)
    load_before = os.getloadavg()
    out = args.cache / "results"
    first_s, alone_sets = stages_alone(paths)  # before and after the campaigns: the load drifts
    # 1, 2, 1 workers: the 1-worker time is the mean of the runs before and after (order and drift)
    one_a, sets, summaries, one_cpu = batch_rate(paths, 1, out, args.batched_fits)
    two_s, _, _, two_cpu = batch_rate(paths, 2, out, args.batched_fits)
    one_b, _, _, _ = batch_rate(paths, 1, out, args.batched_fits)
    one_s = (one_a + one_b) / 2
    last_s, _ = stages_alone(paths)
    alone_s = (first_s + last_s) / 2
    load_after = os.getloadavg()
    stage = {k: sum(getattr(s, f"{k}_s") for s in summaries) for k in ("phase", "aperture", "unwrap", "fit")}
    total = sum(stage.values()) or 1.0
    print(f"campaign: {len(paths)} recordings, {sets} sets (256 x 256, 5 frames each), cores: {os.cpu_count()}"
          + (", batched fits" if args.batched_fits else ""))
    print(f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f} (shared machine: ratios, not rates)")
    print(f"1 worker : {sets / one_s:7.2f} sets/s ({one_s:.2f} s: mean of {one_a:.2f} s before and {one_b:.2f} s "
          "after the 2-worker run)")
    print(f"2 workers: {sets / two_s:7.2f} sets/s ({two_s:.2f} s), {one_s / two_s:.2f}x the 1-worker rate "
          "(target >= 1.7x)")
    print(f"stages alone, one process: {1e3 * alone_s / alone_sets:.1f} ms/set (mean of {1e3 * first_s / alone_sets:.1f}"
          f" before and {1e3 * last_s / alone_sets:.1f} after the campaigns); batch on 1 worker "
          f"{1e3 * one_s / sets:.1f} ms/set, {one_s / sets / (alone_s / alone_sets):.2f}x (target <= 1.5x)")
    for label, use, wall in (("1 worker ", one_cpu, one_s), ("2 workers", two_cpu, two_s)):
        print(f"CPU s, {label} ({wall:.2f} s wall): client main thread {use.client_main:.2f}, client's other "
              f"threads (scheduler, comms) {use.client_other:.2f}, workers "
              + " + ".join(f"{w:.2f}" for w in use.workers) + f", nannies {use.nannies:.2f}; workers busy "
              + ", ".join(f"{100 * b:.0f} %" for b in use.busy) + " of the wall time")
    bound = 2 * sum(one_cpu.workers) / (sum(two_cpu.workers) + two_cpu.client_main + two_cpu.client_other)
    print(f"from the CPU times: on 2 free cores the 2-worker run could reach {bound:.2f}x (twice the 1-worker "
          "run's worker CPU over all the 2-worker run's CPU: workers, client, scheduler)")
    print("share of the workers' stage time: " + ", ".join(f"{k} {100 * v / total:.0f} %" for k, v in stage.items())
          + " (aperture includes the fitter builds of each recording's first set)")


if __name__ == "__main__":  # the workers are spawned: nothing may run on import
    main()
