"""The station's result loop: newest set -> processing -> result -> PLC, recording, display.

One pipeline thread (the caller's) takes the newest set from the source and runs one cycle, one
way, one value per arrow: the processor (the pipeline's
:class:`~wavestack.pipeline.instrument.PhaseShiftingProcessor` or
:class:`~wavestack.pipeline.instrument.CarrierProcessor` for an interferometer, given the station's
:class:`~wavestack.station.fitter_cache.FitterCache` as its fitter source; a
:class:`~wavestack.pipeline.instrument.ShackHartmannProcessor` for a Shack-Hartmann sensor) returns a
frozen outcome; :func:`~wavestack.station.cycle.make_result` makes the
:class:`~wavestack.station.results.StationResult`; the output stage sends it through the safety
stage to the PLC (with a heartbeat each cycle, so a stalled pipeline is a dead host to the PLC's
watchdog) and returns what it sent; every sink gets one
:class:`~wavestack.station.cycle.CycleRecord`. Acquisition runs on the camera's reader thread and
the station's stepping thread, each one thread for the whole run, across reconnects
(:mod:`~wavestack.drivers.role_thread`); fitter builds on the fitter cache's worker. On a simulated camera the devices bring a
:class:`~wavestack.station.truth.TruthCheck`; the loop knows no simulator type.

A device lost while running does not end the run: the result says so (invalid, never forwarded),
the station reopens the camera or the piezo with a capped back-off
(:func:`~wavestack.station.devices.reconnect_devices`), re-applies its configuration and goes on.
The lost connection's source is retired (what it still held counts as dropped) and a new source
counts on from there (after its first result the reference cycles the fault's errors left are
collected: :meth:`~wavestack.station.heap.HeapRelease.after_fault`), so the run's frame and set counters
(:class:`~wavestack.station.counters.Counters`) add up across reconnects and only grow. Counts
that do not add up (a bug) make the result invalid, with the reason, logged at ERROR; the result
carries the last consistent counters.

A device fault is not a host fault: while the loop waits for a set or backs off, it waits in
slices of at most the heartbeat period (a quarter of the PLC watchdog time) and keeps the PLC's
heartbeat alive between them (:meth:`PlcOutput.keep_alive`, a heartbeat, never a command). A set
is processed, and its surface figures taken, on the processing thread (one thread for the whole
run) while the loop waits for it the same way, so the first aperture's detection, the first fitter
and surface analyzer builds and the first compilation (seconds on a loaded machine) never starve
the watchdog at start; but each for at most
``[station] max_processing_s``: processing that takes longer gets no more heartbeats, and the
watchdog trips. A stalled loop (a device call that does not return) beats nothing either. The
stop event is seen within one slice.
"""

from __future__ import annotations

import dataclasses

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from typing import Any, TypeVar, Union

from wavestack.config import BIT_DEPTH, StationConfig
from wavestack.drivers.errors import DeviceDisconnected, DeviceError, DeviceTimeout, renewed
from wavestack.drivers.frames import Frame
from wavestack.drivers.ring import WaitTimeout
from wavestack.drivers.role_thread import RoleThread
from wavestack.station.counters import Counters
from wavestack.station.cycle import CycleRecord, ResultSink, make_result, with_output
from wavestack.station.surface_stage import surface_stage
from wavestack.station.devices import StationDevices, phase_steps_rad, reconnect_devices
from wavestack.pipeline.instrument import (
    CarrierProcessor,
    FitterSource,
    InterferometerSettings,
    PhaseShiftingProcessor,
    SyncFitterSource,
    processor_for,
)
from wavestack.station.fitter_cache import FitterCache
from wavestack.station.heap import HeapRelease
from wavestack.station.latency import LatencyHistogram
from wavestack.station.outputs import PlcOutput
from wavestack.station.results import StationResult, json_ready
from wavestack.pipeline.instrument import ShackHartmannProcessor, SlopeOutcome
from wavestack.station.sources import CarrierSource, PhaseStepSource

logger = logging.getLogger(__name__)
_T = TypeVar("_T")

__all__ = ["ResultSink", "Station", "StationSummary", "build_processor", "interferometer_settings"]

Processor = Union[PhaseShiftingProcessor, CarrierProcessor, ShackHartmannProcessor]

_MAX_WAIT_SLICE_S = 0.25  # longest wait between looks at the stop event (and heartbeats, when shorter)
_FIRST_BACKOFF_S = 0.05


@dataclass(frozen=True)
class StationSummary:
    """How a run went."""

    results: int
    valid: int
    duration_s: float
    results_per_s: float
    latency_p50_ms: float
    latency_p99_ms: float
    counters: Counters
    aperture_changes: int
    fallback_results: int
    stage_ms: dict[str, float] = field(default_factory=dict)
    last_reason: str | None = None

    def to_json(self) -> dict[str, object]:
        return {"type": "summary", **json_ready(asdict(self))}


class _Tally:
    """What the summary counts, result by result, in constant memory (latencies in a histogram)."""

    def __init__(self) -> None:
        self.latencies = LatencyHistogram()
        self.stage_totals: dict[str, float] = {}
        self.processed = self.valid = self.aperture_changes = self.fallbacks = 0
        self.last_reason: str | None = None

    def add(self, result: StationResult) -> None:
        self.latencies.add(result.latency_ms)
        self.processed += 1
        for stage, ms in result.timings_ms.items():
            self.stage_totals[stage] = self.stage_totals.get(stage, 0.0) + ms
        self.valid += result.valid
        self.aperture_changes += result.aperture_changed
        self.fallbacks += result.fitter_fallback
        if not result.valid:
            self.last_reason = result.reason

    def summary(self, results: int, duration: float, counters: Counters) -> StationSummary:
        return StationSummary(
            results=results, valid=self.valid, duration_s=duration,
            results_per_s=results / duration if duration else 0.0,
            latency_p50_ms=self.latencies.percentile(50), latency_p99_ms=self.latencies.percentile(99),
            counters=counters, aperture_changes=self.aperture_changes, fallback_results=self.fallbacks,
            stage_ms={k: v / max(1, self.processed) for k, v in self.stage_totals.items()},
            last_reason=self.last_reason)


class Station:
    """Runs the result loop on open devices.

    Parameters
    ----------
    config : StationConfig
    devices : StationDevices
    """

    def __init__(self, config: StationConfig, devices: StationDevices) -> None:
        self._config = config
        self._devices = devices
        self._fitters = FitterCache(config.processing.fit_settings()) if config.station.kind != "shack-hartmann" else None
        self.processor = build_processor(config, self._fitters)
        # one stepping thread for every source: a new one per reconnect would get a new malloc arena
        self._stepping = RoleThread("phase-step-acquisition") if config.phase_stepping else None
        self._processing = RoleThread("station-processing")
        self._source: CarrierSource | PhaseStepSource | None = self._make_source()
        self._retired = Counters.zero(self._source.frames_per_set)  # sources of lost connections
        self._last_counters = self._retired  # the last snapshot that added up
        self._not_back = DeviceDisconnected(devices.camera.name, "acquisition not started")  # while no source
        self._output: PlcOutput | None = None
        self._surface = surface_stage(config)
        self._slice_s = _MAX_WAIT_SLICE_S
        self._heap = HeapRelease(config.station.heap_release_s)
        if devices.link is not None and config.plc is not None:
            heartbeat_period_s = config.plc.link.watchdog_timeout_s / 4
            self._output = PlcOutput(devices.link, config.outputs, config.plc.link.n_terms,
                                     wavelength_nm=config.station.wavelength_nm,
                                     max_age_s=config.station.max_result_age_s,
                                     timeout_s=config.plc.link.io_timeout_s * 4,
                                     heartbeat_period_s=heartbeat_period_s,
                                     spec_configured=self._surface is not None
                                     and self._surface.request.tolerance is not None,
                                     surface_factor=config.surface.surface_factor if self._surface else None)
            self._slice_s = min(_MAX_WAIT_SLICE_S, heartbeat_period_s)

    def _make_source(self) -> CarrierSource | PhaseStepSource:
        config, devices = self._config, self._devices
        if not config.phase_stepping:  # carrier frames, or Shack-Hartmann spot frames
            return CarrierSource(devices.camera)
        assert devices.piezo is not None and devices.calibration is not None and config.pzt is not None
        return PhaseStepSource(devices.camera, devices.piezo, axis=config.pzt.phase_axis,
                               steps_rad=phase_steps_rad(config), calibration=devices.calibration,
                               settle_s=config.pzt.settle_s, timeout_s=config.camera.timeout_s,
                               ring_capacity=config.station.set_ring_capacity,
                               frame_timeout_s=config.station.frame_timeout_s, role=self._stepping)

    def close(self) -> None:
        """Stop acquisition and the fitter worker; idempotent."""
        if self._source is not None:
            self._source.stop()
        if self._stepping is not None:  # the source's stop waited for the stepping already
            self._stepping.close(timeout_s=self._config.camera.timeout_s * 2 + 5.0)
        self._processing.close(timeout_s=self._config.station.max_processing_s + 5.0)
        if self._fitters is not None:
            self._fitters.close()

    # ------------------------------------------------------------------ the loop

    def run(self, *, stop: threading.Event, on_result: ResultSink, max_results: int | None = None,
            duration_s: float | None = None) -> StationSummary:
        """Produce results until ``stop`` is set, ``max_results`` results or ``duration_s`` seconds.

        ``on_result`` gets one :class:`~wavestack.station.cycle.CycleRecord` per result.

        Returns
        -------
        StationSummary
        """
        started = time.monotonic()
        tally = _Tally()
        index = failures = 0
        backoff_s = _FIRST_BACKOFF_S
        if self._source is not None:
            self._start_source()
        outage = False  # a device fault was handled and no set has come since
        while not stop.is_set():
            if max_results is not None and index >= max_results:
                break
            if duration_s is not None and time.monotonic() - started >= duration_s:
                break
            lost: tuple[StationResult, bool] | None = None  # the invalid result, and whether the camera failed
            try:
                frames = self._read_set(stop)
            except DeviceError as error:  # only its text leaves: its traceback holds the lost source
                frames, lost = None, (self._device_lost(index, error), error.device == self._devices.camera.name)
            if lost is not None:  # recovered outside the handler, so the lost source is freed before a new one
                result, camera_failed = lost
                on_result(CycleRecord(result))
                index += 1
                tally.last_reason = result.reason
                failures += camera_failed  # the camera's own, in a row
                self._recover(stop, backoff_s, force_camera=failures > 2)
                backoff_s = min(backoff_s * 2, self._config.station.reconnect_max_s)
                outage = True
                continue
            if frames is None:  # stopped while waiting
                break
            failures, backoff_s = 0, _FIRST_BACKOFF_S
            record = self._cycle(index, frames)
            on_result(record)
            index += 1
            tally.add(record.result)
            del record, frames  # the set's arrays are freed before the heap is trimmed
            if outage:  # back, the result out: once per outage, collect the cycles its errors were in
                self._heap.after_fault(time.monotonic())
                outage = False
            else:
                self._heap.maybe_release(time.monotonic())
        return tally.summary(index, time.monotonic() - started, self._counters()[0])

    def _read_set(self, stop: threading.Event) -> tuple[Frame, ...] | None:
        """The next set within ``frame_timeout_s``, awaited in slices with the PLC kept alive; None if stopped."""
        if self._source is None:  # a fresh error: each raise of one instance would add to its traceback
            raise renewed(self._not_back)
        timeout_s = self._config.station.frame_timeout_s
        deadline = time.monotonic() + timeout_s
        while not stop.is_set():
            remaining = deadline - time.monotonic()
            try:
                return self._source.read_set(max(0.0, min(self._slice_s, remaining)))
            except WaitTimeout:
                if remaining <= self._slice_s:
                    raise DeviceTimeout(self._devices.camera.name,
                                        f"expected a set within frame_timeout_s = {timeout_s:g} s, got none") from None
            self._keep_alive()
        return None

    def _keep_alive(self) -> None:
        if self._output is not None:
            self._output.keep_alive(time.monotonic())

    def _wait(self, stop: threading.Event, seconds: float) -> bool:
        """Wait ``seconds`` in slices, keeping the PLC alive; True if stopped."""
        deadline = time.monotonic() + seconds
        while (remaining := deadline - time.monotonic()) > 0:
            if stop.wait(min(self._slice_s, remaining)):
                return True
            self._keep_alive()
        return stop.is_set()

    def _cycle(self, index: int, frames: tuple[Frame, ...]) -> CycleRecord:
        """One set, one way: outcome -> result -> output -> the record of the cycle."""
        check = self._devices.truth_check
        truth = check.capture(frames[0]) if check is not None else None  # at once: the simulator forgets
        pixels = [f.pixels for f in frames]
        outcome = self._off_loop(lambda: self.processor.process(pixels))
        errors = check.compare(truth, outcome) if check is not None and truth is not None else None
        counters, miscount = self._counters()
        result = make_result(index, frames, outcome, ordering=self._config.processing.ordering,
                             counters=counters, now_ns=time.time_ns(), truth=errors)
        if miscount is not None:  # never a wrong number, never a dead station: an invalid result
            result = replace(result, valid=False, reason=miscount)
        waves = None if isinstance(outcome, SlopeOutcome) else outcome.waves
        if self._surface is not None and result.valid and waves is not None:  # before the PLC: it shows them
            stage = self._surface
            result = replace(result, surface=self._off_loop(lambda: stage.record(index, waves)))
        sent = self._output.send(result) if self._output is not None else None
        slopes = isinstance(outcome, SlopeOutcome)
        return CycleRecord(with_output(result, sent, now_ns=time.time_ns()), frames, outcome.new_aperture_mask,
                           outcome.lenslets if slopes else None, waves, None if slopes else outcome.flags)

    def _off_loop(self, compute: Callable[[], _T]) -> _T:
        """``compute()`` (a set's processing, its surface figures) on the processing thread while the
        loop keeps the PLC alive for at most ``max_processing_s`` (module notes); its exception, if it
        raised."""
        box: list[tuple[bool, Any]] = []

        def work() -> None:
            try:
                box.append((True, compute()))
            except BaseException as error:  # noqa: BLE001 - raised again on the loop's thread
                box.append((False, error))

        job = self._processing.run(work)
        started, budget_s, said = time.monotonic(), self._config.station.max_processing_s, False
        while True:
            job.join(self._slice_s)
            if not job.is_alive():
                break
            if time.monotonic() - started <= budget_s:
                self._keep_alive()
            elif not said:
                logger.error("processing a set has taken over max_processing_s = %g s: no more heartbeats until it "
                             "returns (the PLC watchdog trips)", budget_s)
                said = True
        ok, value = box.pop()
        if not ok:
            try:
                raise value
            finally:  # no local naming the error: a cycle with this frame
                del value
        return value

    def _recover(self, stop: threading.Event, wait_s: float, *, force_camera: bool) -> None:
        """After a device fault: retire the source, back off, bring the devices back, start a new source.

        The lost source is read no more: what it still held is counted dropped. A device not back
        yet leaves no source; the next cycle reports it and backs off longer.
        """
        self._retire_source()
        if self._wait(stop, wait_s):
            return
        try:
            reconnect_devices(self._devices, self._config, force_camera=force_camera)
        except DeviceError as error:
            logger.warning("devices still unavailable: %s", error)
            self._not_back = DeviceDisconnected(error.device, f"not back yet ({error.detail})")
            return
        self._keep_alive()
        self._source = self._make_source()
        self._start_source()

    def _start_source(self) -> None:
        assert self._source is not None
        try:
            self._source.start()
        except DeviceError as error:  # the next read reports the missing source
            logger.warning("acquisition did not start: %s", error)
            self._not_back = DeviceDisconnected(error.device, f"acquisition did not start ({error.detail})")
            self._retire_source()

    # ------------------------------------------------------------------ records

    def _retire_source(self) -> None:
        source, self._source = self._source, None
        if source is None:
            return
        try:
            source.stop()
        except DeviceError as error:  # a camera already gone may not acknowledge the stop
            logger.info("stopping the lost source: %s", error)
        self._devices.camera.discard_pending()  # counted dropped with the source, not again by the next
        try:
            self._retired = self._retired.plus(source.counters().retired())
        except ValueError as error:  # keep the last consistent counts: they still only grow
            logger.error("counters of the retired source do not add up: %s", error)
            self._retired = self._last_counters.retired()

    def _counters(self) -> tuple[Counters, str | None]:
        """Frames and sets this run (retired sources and the current one), and why they are stale, if they are.

        Counts that do not add up (a bug) are logged at ERROR; the last consistent counts are
        returned with the reason, and the caller makes its result invalid.
        """
        try:
            counters = self._retired if self._source is None else self._retired.plus(self._source.counters())
        except ValueError as error:
            logger.error("station counters do not add up (result made invalid): %s", error)
            return self._last_counters, f"counters: {error}"
        self._last_counters = counters
        return counters, None

    def _device_lost(self, index: int, error: DeviceError) -> StationResult:
        now_ns = time.time_ns()
        result = StationResult.invalid(index, f"device: {error}", self._counters()[0],
                                       ordering=self._config.processing.ordering, exposure_time_ns=now_ns)
        return with_output(result, self._output.device_lost(f"device: {error}", now_ns, index)
                           if self._output is not None else None)


def interferometer_settings(config: StationConfig) -> InterferometerSettings:
    """The interferometer processor's settings of a station: ``[processing]``, saturating at the camera's full scale,
    with its reference calibration (``[processing] calibration``) subtracted from every map."""
    settings = config.processing.interferometer(saturation_counts=float(2 ** BIT_DEPTH[config.camera.pixel_format] - 1))
    return settings if config.calibration is None else dataclasses.replace(settings, calibration=config.calibration)


def build_processor(config: StationConfig, fitters: FitterSource | None = None) -> Processor:
    """The processor of a station's kind: phase maps and fits, or Shack-Hartmann slopes.

    ``fitters``: the interferometer's fitter source (the live station's :class:`FitterCache`);
    None builds every fitter at once (:class:`~wavestack.pipeline.SyncFitterSource`: replay, batch,
    the stage benchmarks), with the same numbers.
    """
    if config.station.kind == "shack-hartmann":
        assert config.shack_hartmann is not None  # parse_station_config requires [shack_hartmann]
        return ShackHartmannProcessor(config.shack_hartmann.setup(config.station.wavelength_nm))
    settings = interferometer_settings(config)
    return processor_for(settings, fitters if fitters is not None else SyncFitterSource(settings.fit))
