"""The station's result loop: newest set -> processing -> result -> PLC, recording, display.

One pipeline thread (the caller's) takes the newest set from the source, processes it (a
:class:`~wavestack.station.processing.SetProcessor` for an interferometer, a
:class:`~wavestack.station.sh_processing.SlopeProcessor` for a Shack-Hartmann sensor), builds the
:class:`~wavestack.station.results.StationResult`, sends it through the safety stage to the PLC
(with a heartbeat each cycle, so a stalled pipeline is a dead host to the PLC's watchdog), records
it and hands it to the caller. Acquisition runs in the source's own threads; fitter builds on the
fitter cache's worker.

A device lost while running does not end the run: the result says so (invalid, never forwarded),
the station reopens the camera with a capped back-off, re-applies its configuration and goes on.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np
from numpy.typing import NDArray

from wavestack.drivers.errors import DeviceDisconnected, DeviceError, DeviceTimeout
from wavestack.drivers.frames import Frame
from wavestack.pipeline import InvalidFrame
from wavestack.simulators.bench import FrameTruth
from wavestack.simulators.spots import SpotTruth
from wavestack.station.devices import StationDevices, configure_camera, phase_steps_rad
from wavestack.station.outputs import PlcOutput
from wavestack.station.fitter_cache import FitterChoice
from wavestack.station.processing import ProcessedSet, SetProcessor
from wavestack.station.results import Counters, StationResult, json_ready
from wavestack.station.settings import StationConfig
from wavestack.station.sh_processing import SlopeProcessor, coefficient_errors
from wavestack.station.sources import CarrierSource, PhaseStepSource

logger = logging.getLogger(__name__)

ResultSink = Callable[[StationResult, tuple[Frame, ...], ProcessedSet], None]


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
        self.processor = build_processor(config)
        self._source = self._make_source()
        self._output = None
        self._truth_key: tuple[int, int] | None = None  # (fitter, aperture revision) of the cached truth line
        self._truth_line: tuple[NDArray, NDArray] = (np.zeros(0), np.zeros(0))
        if devices.link is not None and config.plc is not None:
            self._output = PlcOutput(devices.link, config.outputs, config.plc.link.n_terms,
                                     wavelength_nm=config.station.wavelength_nm,
                                     max_age_s=config.station.max_result_age_s,
                                     timeout_s=config.plc.link.io_timeout_s * 4)

    def _make_source(self) -> CarrierSource | PhaseStepSource:
        config, devices = self._config, self._devices
        if not config.phase_stepping:  # carrier frames, or Shack-Hartmann spot frames
            return CarrierSource(devices.camera)
        assert devices.piezo is not None and devices.calibration is not None and config.pzt is not None
        return PhaseStepSource(devices.camera, devices.piezo, axis=config.pzt.phase_axis,
                               steps_rad=phase_steps_rad(config), calibration=devices.calibration,
                               settle_s=config.pzt.settle_s, timeout_s=config.camera.timeout_s,
                               ring_capacity=config.station.set_ring_capacity)

    def close(self) -> None:
        """Stop acquisition and the fitter worker; idempotent."""
        self._source.stop()
        self.processor.close()

    # ------------------------------------------------------------------ the loop

    def run(self, *, stop: threading.Event, on_result: ResultSink, max_results: int | None = None,
            duration_s: float | None = None) -> StationSummary:
        """Produce results until ``stop`` is set, ``max_results`` results or ``duration_s`` seconds.

        Returns
        -------
        StationSummary
        """
        started = time.monotonic()
        latencies: list[float] = []
        stage_totals: dict[str, float] = {}
        valid = aperture_changes = fallbacks = 0
        last_reason = None
        index = 0
        backoff_s = 0.05
        self._source.start()
        while not stop.is_set():
            if max_results is not None and index >= max_results:
                break
            if duration_s is not None and time.monotonic() - started >= duration_s:
                break
            try:
                frames = self._source.read_set(self._config.station.frame_timeout_s)
            except (DeviceTimeout, DeviceDisconnected, DeviceError) as error:
                result = self._device_lost(index, error)
                on_result(result, (), ProcessedSet(False, result.reason))
                index += 1
                last_reason = result.reason
                self._recover(stop, backoff_s)
                backoff_s = min(backoff_s * 2, self._config.station.reconnect_max_s)
                continue
            backoff_s = 0.05
            truth = self._devices.truth(frames[0])  # at once: a simulator keeps only its recent frames' truth
            processed = self.processor.process([f.pixels for f in frames])
            result = self._result(index, frames, processed, truth)
            on_result(result, frames, processed)
            index += 1
            latencies.append(result.latency_ms)
            for stage, ms in result.timings_ms.items():
                stage_totals[stage] = stage_totals.get(stage, 0.0) + ms
            valid += result.valid
            aperture_changes += bool(result.aperture.get("changed"))
            fallbacks += result.fitter_fallback
            if not result.valid:
                last_reason = result.reason
        duration = time.monotonic() - started
        source = self._source.counters()
        lat = np.asarray(latencies) if latencies else np.asarray([np.nan])
        return StationSummary(
            results=index, valid=valid, duration_s=duration, results_per_s=index / duration if duration else 0.0,
            latency_p50_ms=float(np.percentile(lat, 50)), latency_p99_ms=float(np.percentile(lat, 99)),
            counters=Counters(source.acquired, index, source.dropped), aperture_changes=aperture_changes,
            fallback_results=fallbacks,
            stage_ms={k: v / max(1, len(latencies)) for k, v in stage_totals.items()}, last_reason=last_reason)

    def _recover(self, stop: threading.Event, wait_s: float) -> None:
        """Reopen the camera after a loss and restart acquisition; the caller backs off on failure."""
        self._source.stop()
        if stop.wait(wait_s):
            return
        camera = self._devices.camera
        try:
            camera.reopen(timeout_s=self._config.camera.timeout_s)
            configure_camera(camera, self._config)
            self._source = self._make_source()
            self._source.start()
            logger.info("camera %s is back", camera.name)
        except DeviceError as error:
            logger.warning("camera still unavailable: %s", error)

    # ------------------------------------------------------------------ records

    def _counters(self, processed: int) -> Counters:
        source = self._source.counters()
        return Counters(source.acquired, processed, source.dropped)

    def _device_lost(self, index: int, error: DeviceError) -> StationResult:
        now_ns = time.time_ns()
        output = None
        if self._output is not None:
            output = self._output.publish(None, valid=False, measured_at_s=now_ns * 1e-9, now_s=now_ns * 1e-9,
                                          reason=f"device: {error}")
        return StationResult.invalid(index, f"device: {error}", self._counters(index + 1),
                                     ordering=self._config.processing.ordering, exposure_time_ns=now_ns,
                                     output=output)

    def _result(self, index: int, frames: tuple[Frame, ...], processed: ProcessedSet,
                truth: FrameTruth | SpotTruth | None = None) -> StationResult:
        settings = self._config.processing
        exposure_ns = frames[0].host_time_ns
        truth_rms = truth_error = None
        if processed.valid and truth is not None:
            truth_rms, truth_error = self._truth_errors(truth, processed)
        output = None
        if self._output is not None:
            output = self._output.heartbeat()
            now_ns = time.time_ns()
            output.update(self._output.publish(processed.coefficients_waves, valid=processed.valid,
                                               measured_at_s=exposure_ns * 1e-9, now_s=now_ns * 1e-9,
                                               reason=processed.reason))
        choice, fit, aperture = processed.choice, processed.fit, processed.aperture
        diagnostics = dict(processed.fitter_diagnostics)
        if choice is not None:
            d = choice.fitter.diagnostics
            diagnostics = {"gram_condition": d.gram_condition, "flips": d.flips, "max_beltrami": d.max_beltrami}
        aperture_record = dict(processed.aperture_record)
        if aperture is not None:
            aperture_record = {"id": choice.aperture_id if choice else None, "changed": processed.aperture_changed,
                               "topology": aperture.describe(), "components": aperture.components,
                               "valid_pixels": int(aperture.mask.sum())}
        latency_ms = (time.time_ns() - exposure_ns) * 1e-6
        return StationResult(
            index=index, frame_ids=tuple(f.frame_id for f in frames), exposure_time_ns=exposure_ns,
            latency_ms=latency_ms, valid=processed.valid, reason=processed.reason,
            coefficients=tuple(float(c) for c in processed.coefficients_waves)
            if processed.coefficients_waves is not None else (),
            ordering=settings.ordering, normalisation=fit.basis.normalisation if fit is not None else "rms",
            units="waves", residual_rms=fit.residual_rms if fit is not None else processed.residual_rms,
            fitter=choice.kind if choice else processed.fitter_kind, fitter_fallback=bool(choice and choice.fallback),
            fitter_diagnostics=diagnostics, aperture=aperture_record, unwrap_path=processed.unwrap_path,
            counters=self._counters(index + 1),
            timings_ms={k: v * 1e3 for k, v in processed.timings_s.items()},
            truth_rms=truth_rms, truth_error_rms=truth_error, output=output)

    def _truth_errors(self, truth: FrameTruth | SpotTruth,
                      processed: ProcessedSet) -> tuple[float | None, float | None]:
        """RMS of the true wavefront and of measured minus true, in the fitted subspace (simulators only).

        Shack-Hartmann: from the coefficients, both in the unit-RMS circle basis over the pupil
        disk, Noll 4 onwards (:func:`~wavestack.station.sh_processing.coefficient_errors`).
        """
        if isinstance(truth, SpotTruth):
            if processed.coefficients_waves is None:
                return None, None
            return coefficient_errors(processed.coefficients_waves, truth.coefficients_waves)
        if processed.choice is None or processed.fit is None:
            return None, None
        assert isinstance(self.processor, SetProcessor)  # a FitterChoice comes only from a SetProcessor
        fitter = processed.choice.fitter
        if truth.source.aperture_revision != truth.aperture_revision:
            return None, None  # the optic's aperture changed after this frame: its truth is gone
        try:
            at_zero, per_second = self._true_coefficients(truth, processed.choice)
        except InvalidFrame as error:  # the optic's aperture changed within the set: nothing to compare
            logger.debug("no truth comparison: %s", error)
            return None, None
        true_coefficients = at_zero + truth.time_s * per_second
        # RMS over the fitted samples from the orthonormal form (no pass over the operator)
        return (fitter.surface_rms(true_coefficients),
                fitter.surface_rms(processed.fit.coefficients - true_coefficients))

    def _true_coefficients(self, truth: FrameTruth, choice: FitterChoice) -> tuple[NDArray, NDArray]:
        """The simulator's true coefficients in this fitter's basis, as ``a + t b``.

        The simulated optic drifts linearly in time and the fit is linear in the map, so the true
        coefficients at any frame time follow from two fits per fitter and aperture revision (at
        t = 0 and t = 1 s) instead of one fit of a freshly rendered 8 MB map per result.
        """
        key = (id(choice.fitter), truth.aperture_revision)
        if self._truth_key != key:
            assert isinstance(self.processor, SetProcessor)
            start = self.processor.fit_map(truth.source.truth(0.0).wavefront_waves, choice).coefficients
            later = self.processor.fit_map(truth.source.truth(1.0).wavefront_waves, choice).coefficients
            self._truth_key, self._truth_line = key, (start, later - start)
        return self._truth_line


def build_processor(config: StationConfig, *, background_builds: bool = True) -> SetProcessor | SlopeProcessor:
    """The processor of a station's kind: phase maps and fits, or Shack-Hartmann slopes.

    ``background_builds=False`` builds fitters synchronously (replay, benchmarks of the stages).
    """
    if config.station.kind == "shack-hartmann":
        assert config.shack_hartmann is not None  # parse_station_config requires [shack_hartmann]
        return SlopeProcessor(config.shack_hartmann, wavelength_nm=config.station.wavelength_nm)
    return SetProcessor(config.processing, background_builds=background_builds)
