"""``wavestack bench station``: the station's speed on the simulated bench, path by path.

For each path -- the carrier path (the configuration with ``[processing] method = "carrier"``
and tilt fringes on the optic) and the phase-stepping path (the configuration as is) -- one run
of the real station on its simulated devices measures:

* results per second and latency p50/p99 over ``N`` results, after a warm-up that ends once
  results come from the configured fitter (no longer the ``qr`` stand-in) of the first aperture;
* the mean time per stage (``StationResult.timings_ms``) and the per-result time ``1 / rate``;
  then the same stages alone: the station's processor's ``process`` in a loop on sets recorded during the
  run, with no device running. ``per-result time / alone stage sum`` is the overhead the station
  adds (target <= 1.5);
* the simulator's share of the process CPU time. Camera: the thread CPU time
  (``time.thread_time``) spent inside the simulated USB backend's ``bulk_read`` and
  ``bulk_write`` (rendering the optic -- also timed alone --, encoding the payload, copying it
  into the host's buffer). Piezo: thread CPU time inside ``MDT693BDevice.feed``. PLC: the CPU time
  of the simulator's server thread (pymodbus on its own asyncio loop), read from
  ``/proc/self/task`` like the CPU time of every other thread. Process CPU: ``time.process_time``;
* the aperture change: the optic's aperture is changed mid-run; the times from the change to the
  first result that detects it (``aperture.changed``) and to the first result on the configured
  fitter of the new aperture ("results from the new map").

Nothing is asserted: the figures are printed beside the targets with a pass/miss mark (the
machine may be shared and noisy; the load average at the start is printed).

The CPU accounting lives in :mod:`wavestack.bench.station_cpu`; the figures, the targets and their
text and JSON forms in :mod:`wavestack.bench.station_figures`; the command itself (options,
printing) in :mod:`wavestack.cli.bench`.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Sequence
from contextlib import ExitStack
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wavestack.bench.station_cpu import _instrument, _Mark, _mark, _Meter, _per_result_ms
from wavestack.bench.station_figures import STAGES, MachineState, StationPathFigures
from wavestack.config import StationConfig
from wavestack.drivers.errors import DeviceError
from wavestack.simulators.optic import ApertureShape
from wavestack.station import CycleRecord, Station, StationDevices, StationResult, build_processor, open_station_devices

logger = logging.getLogger(__name__)

CARRIER_CYCLES = (60.0, 35.0)  # tilt fringes across the frame (see carrier_config)
WARMUP_EXTRA = 2  # results on the configured fitter before the measurement starts
RECORDED_SETS = 8  # sets kept for the stage benchmark (a 1024 x 1024 five-frame set is 10 MB)
WARMUP_LIMIT_S = 90.0
CHANGE_LIMIT_S = 30.0


def machine_state() -> MachineState:
    """CPUs, the 1-minute load average (other processes share the cores) and the BLAS thread setting."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return MachineState(cpus=os.cpu_count(), load_average_1min=load,
                        openblas_num_threads=os.environ.get("OPENBLAS_NUM_THREADS", "unset"))


def carrier_config(config: StationConfig, cycles: tuple[float, float] | None = None) -> StationConfig:
    """The carrier variant of a simulated station: ``method = "carrier"``, tilt fringes, no piezo.

    Parameters
    ----------
    config : StationConfig
        A simulated station.
    cycles : (float, float), optional
        Fringes across the width and height; default: the optic's own carrier, or (60, 35) cycles
        whatever the frame size. The sideband's spread is set by the optic's aberration (about
        20 cycles across the aperture here), not by the pixel count, so the carrier must stay
        that far from DC: scaled down to (15, 9) on a 256-pixel frame it overlaps the background
        and every result is flagged (measured 0.17 waves of residual).
    """
    assert config.optic is not None
    if cycles is None:
        cycles = config.optic.carrier_cycles
        if not any(cycles):
            cycles = CARRIER_CYCLES
    return replace(config, processing=replace(config.processing, method="carrier"),
                   optic=replace(config.optic, carrier_cycles=(float(cycles[0]), float(cycles[1]))),
                   pzt=None, pzt_simulator=None)


def changed_aperture(width: int, height: int) -> ApertureShape:
    """The aperture the optic is switched to mid-run: a tilted ellipse, nothing like the annulus."""
    return ApertureShape(kind="ellipse", centre_px=(0.5 * width, 0.5 * height),
                         semi_axes_px=(0.40 * width, 0.30 * height), rotation_deg=25.0)


# ---------------------------------------------------------------------------------- the run


class _PathRun:
    """The result sink of one path: warm-up, measurement, aperture change; sets ``stop`` when done."""

    def __init__(self, devices: StationDevices, results: int, meters: tuple[_Meter, _Meter], stop: threading.Event,
                 new_aperture: ApertureShape) -> None:
        self.devices, self.wanted, self.meters, self.stop = devices, results, meters, stop
        self.new_aperture = new_aperture
        self.state = "warmup"
        self.started = time.perf_counter()
        self.warmup_s = 0.0
        self.warmup_results = self.on_fitter = self.changes = 0
        self.measured: list[StationResult] = []
        self.arrivals_ms: list[float] = []
        self.recorded: list[list[NDArray[Any]]] = []
        self.marks: list[_Mark] = []
        self.counters: list[tuple[int, int]] = []  # (acquired, dropped) at the start and end of the window
        self.set_aperture_s: float | None = None
        self.detect_s: float | None = None
        self.new_map_s: float | None = None
        self.changed_at = 0.0
        self.detected_id: int | None = None

    def __call__(self, record: CycleRecord) -> None:
        now = time.perf_counter()
        result, frames = record.result, record.frames
        if self.state == "warmup":
            self.warmup_results += 1
            self.on_fitter += result.valid and not result.fitter_fallback
            if self.on_fitter >= WARMUP_EXTRA:
                self.state, self.warmup_s = "measure", now - self.started
                self._take_mark(result)
            elif now - self.started > WARMUP_LIMIT_S:
                logger.warning("no result on the configured fitter after %.0f s; stopping", WARMUP_LIMIT_S)
                self.stop.set()
        elif self.state == "measure":
            self.measured.append(result)
            if len(frames) > 1:
                self.arrivals_ms.append((frames[-1].host_time_ns - frames[0].host_time_ns) * 1e-6)
            if len(self.recorded) < RECORDED_SETS and result.valid:
                self.recorded.append([f.pixels for f in frames])
            if len(self.measured) >= self.wanted:
                self._take_mark(result)
                self._change_aperture()
        elif self.state == "change":
            self._follow_change(result, now)

    def _take_mark(self, result: StationResult) -> None:
        self.marks.append(_mark(self.devices, *self.meters))
        frames = result.counters.frames
        self.counters.append((frames.acquired, frames.dropped))

    def _change_aperture(self) -> None:
        assert self.devices.bench is not None
        tick = time.perf_counter()
        self.devices.bench.optic.set_aperture(self.new_aperture)
        self.changed_at = time.perf_counter()
        self.set_aperture_s = self.changed_at - tick
        self.state = "change"

    def _follow_change(self, result: StationResult, now: float) -> None:
        aperture_id = result.aperture.id if result.aperture is not None else None
        if result.aperture_changed:
            self.changes += 1
            if self.detect_s is None:
                self.detect_s, self.detected_id = now - self.changed_at, aperture_id
        if (self.detected_id is not None and aperture_id is not None and aperture_id >= self.detected_id
                and result.valid and not result.fitter_fallback):
            self.new_map_s, self.state = now - self.changed_at, "done"
            self.stop.set()
        elif now - self.changed_at > CHANGE_LIMIT_S:
            logger.warning("no result from the new aperture's map within %.0f s", CHANGE_LIMIT_S)
            self.stop.set()


def _stage_benchmark(config: StationConfig, sets: Sequence[Sequence[NDArray[Any]]],
                     runs: int) -> tuple[dict[str, float], float]:
    """Mean ms per stage and per ``process`` call of a fresh processor on recorded sets, no devices."""
    processor = build_processor(config)  # the station's processor, its fitters built at once
    totals = dict.fromkeys(STAGES, 0.0)
    wall, valid = 0.0, 0
    processor.process(sets[0])  # aperture detection and the synchronous fitter build
    for index in range(runs):
        tick = time.perf_counter()
        processed = processor.process(sets[index % len(sets)])
        wall += time.perf_counter() - tick
        valid += processed.valid
        for stage in STAGES:
            totals[stage] += processed.timings_s.get(stage, 0.0) if processed.valid else 0.0
    return {stage: totals[stage] * 1e3 / max(valid, 1) for stage in STAGES}, wall * 1e3 / runs


def _describe(name: str, config: StationConfig) -> str:
    s, sim, optic = config.processing, config.camera_simulator, config.optic
    what = (f"carrier {optic.carrier_cycles[0]:g} x {optic.carrier_cycles[1]:g} cycles"
            if name == "carrier" and optic is not None else f"{len(s.steps_deg)} steps, {s.psi_algorithm}")
    return f"{s.method}, {sim.width} x {sim.height} {sim.pixel_format}, {what}, {s.fit_method} / {s.modes} modes"


def measure_path(name: str, config: StationConfig, results: int) -> StationPathFigures:
    """Run the station of ``config`` on its simulated devices and measure one path.

    Parameters
    ----------
    name : str
        "carrier" or "psi" (a label).
    config : StationConfig
        A simulated station (``sim://u3v``).
    results : int
        Results measured after the warm-up.

    Returns
    -------
    StationPathFigures

    Raises
    ------
    DeviceError
        Fewer results than asked for within the time limits (the log says why).
    """
    meters, stop, sim = (_Meter(time.thread_time), _Meter(time.perf_counter)), threading.Event(), config.camera_simulator
    with ExitStack() as stack:
        devices = open_station_devices(config, stack)
        _instrument(devices, *meters)
        station = Station(config, devices)
        stack.callback(station.close)
        run = _PathRun(devices, results, meters, stop, changed_aperture(sim.width, sim.height))
        station.run(stop=stop, on_result=run, duration_s=WARMUP_LIMIT_S + CHANGE_LIMIT_S + 5.0 * results)
    if len(run.measured) < results or len(run.marks) < 2 or not run.recorded:
        raise DeviceError(f"simulated station ({name} path)", f"expected {results} results after the warm-up, got "
                          f"{len(run.measured)} after {run.warmup_results} warm-up results; see the log (-v)")
    (start, end), n = run.marks, len(run.measured)
    elapsed = end.wall_s - start.wall_s
    latencies = np.array([r.latency_ms for r in run.measured])
    per_stage = {stage: np.array([r.timings_ms.get(stage, np.nan) for r in run.measured]) for stage in STAGES}
    alone, alone_ms = _stage_benchmark(config, run.recorded, results)
    threads = _per_result_ms(start.threads, end.threads, n)
    simulators = {"camera": 0.0, **_per_result_ms(start.simulators, end.simulators, n), "plc": threads.get("plc", 0.0)}
    process_ms = (end.process_s - start.process_s) * 1e3 / n
    stage_ms = {k: float(np.nanmean(v)) for k, v in per_stage.items()}
    return StationPathFigures(
        path=name, description=_describe(name, config), results=n, warmup_results=run.warmup_results,
        warmup_s=run.warmup_s, results_per_s=n / elapsed, per_result_ms=elapsed * 1e3 / n,
        latency_p50_ms=float(np.percentile(latencies, 50)), latency_p99_ms=float(np.percentile(latencies, 99)),
        stage_ms=stage_ms, outside_stages_ms=elapsed * 1e3 / n - sum(stage_ms.values()),
        plc_io_ms=(end.io_wall.get("plc", 0.0) - start.io_wall.get("plc", 0.0)) * 1e3 / n,
        plc_requests_per_result=(end.plc_requests - start.plc_requests) / n,
        stage_median_ms={k: float(np.nanmedian(v)) for k, v in per_stage.items()},
        alone_stage_ms=alone, alone_process_ms=alone_ms, alone_runs=results,
        overhead_ratio=elapsed * 1e3 / n / max(sum(alone.values()), 1e-9), process_cpu_ms=process_ms,
        simulator_cpu_ms=simulators,
        simulator_share=(simulators["camera"] + simulators.get("piezo", 0.0) + simulators["plc"]) / process_ms,
        thread_cpu_ms=threads, set_arrival_ms=float(np.median(run.arrivals_ms)) if run.arrivals_ms else 0.0,
        frames_acquired=run.counters[1][0] - run.counters[0][0], frames_dropped=run.counters[1][1] - run.counters[0][1],
        aperture_set_s=run.set_aperture_s, aperture_detect_s=run.detect_s, aperture_new_map_s=run.new_map_s,
        aperture_changes=run.changes,
    )
