"""An alignment session: the bench's devices opened and the loop's pieces built from the configuration.

:func:`open_session` builds what :class:`~.loop.AlignmentLoop` takes: the design model, the fitter
on the pupil's aperture, the field stage's target per field point, the opened hexapod and field
stage drivers and the measurement.

- ``[align] simulated = true``: the simulator starter (:func:`wavestack.simulated.start_align_bench`,
  imported only then) starts the simulated bench (both PI simulators on loopback, the as-built
  telescope with a seeded mount error) and the session measures the bench's wavefront maps, or
  with ``[align] station`` the station's maps through the simulated camera (:mod:`.station_source`,
  the telescope coupled to the station's optic).
- ``[align] simulated = false`` (a real bench, :func:`open_real_session`): nothing simulated is
  started; the drivers open ``[hexapod] url`` and ``[field_stage] url``, the measurement is the
  station of ``[align] station`` (required) on its own devices, and the loop fits and judges
  without tilt (:class:`~.terms.TermFitter` ``remove_tilt``): the reference's tip/tilt setting at
  each field point is the operator's and is not known to the loop (docs/alignment.md).
"""

from __future__ import annotations

import logging
from contextlib import ExitStack
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wavestack.align.fringes import MAX_SLOPE_WAVES_PER_PX, fringe_slope_bound
from wavestack.align.loop import AlignOptions, FieldMeasurement
from wavestack.align.station_source import StationSource, fixed_aperture, open_station_service
from wavestack.align.terms import TermFitter
from wavestack.config.align import AlignConfig
from wavestack.config.hexapod import HexapodSettings, build_hexapod
from wavestack.drivers.pi_gcs import PIHexapod
from wavestack.pipeline import InputError
from wavestack.pipeline.telescope import HexapodPose, TmaModel

logger = logging.getLogger(__name__)

__all__ = ["AlignSession", "check_fringes", "open_real_session", "open_session", "options_of"]


@dataclass(eq=False)
class AlignSession:
    """What an alignment runs on (the loop's keyword arguments, and the simulated bench for tests: None on a
    real bench)."""

    bench: Any
    hexapod: PIHexapod
    field_stage: PIHexapod
    design: TmaModel
    fitter: TermFitter
    field_positions: list[dict[str, float]]
    station: StationSource | None = None

    def measure(self, index: int, averaged: int = 1) -> FieldMeasurement:
        """Measure at the field point the stage holds: through the station when configured, else the
        average of ``averaged`` renders of the bench (``index`` is for messages)."""
        if self.station is not None:
            return self.station.measure(index)
        if self.bench is None:
            raise ValueError(f"field point {index}: no measurement source")
        frames = [self.bench.wavefront() for _ in range(averaged)]
        waves = np.mean([f.waves for f in frames], axis=0)
        return FieldMeasurement(waves, frames[0].exposure_ns)

    def loop_arguments(self) -> dict[str, object]:
        """Keyword arguments of :class:`~.loop.AlignmentLoop` this session provides."""
        return {"design_model": self.design.wavefront, "fields": self.design.design.field_points_deg,
                "field_positions": self.field_positions, "fitter": self.fitter, "hexapod": self.hexapod,
                "field_stage": self.field_stage, "measure": self.measure}


def options_of(config: AlignConfig, *, max_iterations: int | None = None,
               target_rms_waves: float | None = None) -> AlignOptions:
    """The loop's options from ``[align]`` with the command line's overrides."""
    a = config.align
    return AlignOptions(a.target_rms_waves if target_rms_waves is None else target_rms_waves,
                        max_iterations or a.max_iterations, a.gain, a.rcond, a.min_improvement, a.steps, a.scales,
                        a.readback_tolerance, config.hexapod.move_timeout_s)


def check_fringes(config: AlignConfig, design: TmaModel) -> float:
    """Refuse a camera grid on which the stated misalignment range would alias (:mod:`.fringes`).

    The range is ``[align.simulator]``'s (the draw of the mount error); returns the bound, waves
    per pixel.

    Raises
    ------
    InputError
        The bound exceeds :data:`~.fringes.MAX_SLOPE_WAVES_PER_PX`; the message gives the pixel size
        that would do.
    """
    sim = config.align.simulator
    ranges = np.array([sim.decentre_mm, sim.decentre_mm, sim.despace_mm, sim.tilt_deg, sim.tilt_deg])
    bound = fringe_slope_bound(design.wavefront, config.design.field_points_deg, ranges,
                               null_tilt=config.align.null_tilt)
    if bound > MAX_SLOPE_WAVES_PER_PX:
        pixel = config.design.pixel_mm * MAX_SLOPE_WAVES_PER_PX / bound
        raise InputError(f"{config.source}: [tma] camera_shape/pixel_mm: over the misalignment range of "
                         f"[align.simulator] the fringes reach {bound:.2f} waves per pixel (null_tilt = "
                         f"{str(config.align.null_tilt).lower()}), above {MAX_SLOPE_WAVES_PER_PX:g}; expected "
                         f"pixels of at most {pixel:.3g} mm, a smaller range, or null_tilt = true")
    logger.info("align: fringe slope bound %.3f waves per pixel over the stated range", bound)
    return bound


def _driver(settings: HexapodSettings, stack: ExitStack, url: str | None = None) -> PIHexapod:
    """Open a PI driver on ``url`` (default: the configured one); on a real controller set the configured
    pivot and velocity."""
    driver = build_hexapod(settings if url is None else replace(settings, url=url))
    driver.open()
    stack.callback(driver.close)
    if settings.pivot_mm is not None:
        driver.set_pivot(settings.pivot_mm)
    if settings.velocity is not None:
        driver.set_velocity(settings.velocity)
    return driver


def _field_positions(config: AlignConfig) -> list[dict[str, float]]:
    scale = config.align.field_stage_mm_per_deg
    return [dict(zip(config.field_stage.axes, (fx * scale, fy * scale))) for fx, fy in config.design.field_points_deg]


def open_real_session(config: AlignConfig, stack: ExitStack) -> AlignSession:
    """Open a real bench (module notes); ``stack`` closes everything.

    Raises
    ------
    InputError
        ``[align] station`` absent (a real bench measures through its interferometer station).
    ConfigError, DeviceError
        The station file, or a controller or station device that does not open.
    """
    station_path = config.station_path()
    if station_path is None:
        raise InputError(f"{config.source}: [align] station: required with simulated = false (the station TOML "
                         "of the interferometer: its camera and piezo); expected a path relative to this file")
    design = TmaModel(config.design)
    mask = fixed_aperture(design.pupil_mask, config.align.edge_px)
    fitter = TermFitter(mask, config.align.max_noll, method=config.align.fit_method, remove_tilt=True)
    hexapod = _driver(config.hexapod, stack)
    stage = _driver(config.field_stage, stack)
    service = open_station_service(station_path, stack)
    station = StationSource(service, mask, averaged=config.align.averaged, settle_s=config.align.settle_s,
                            timeout_s=config.align.measure_timeout_s)
    logger.info("align: real bench: hexapod %s, field stage %s, station %s (tilt removed from fit and RMS)",
                config.hexapod.url, config.field_stage.url, station_path)
    return AlignSession(None, hexapod, stage, design, fitter, _field_positions(config), station)


def open_session(config: AlignConfig, stack: ExitStack, *, mount: HexapodPose | None = None,
                 as_built_seed: int | None = None, noise_waves: float = 0.0) -> AlignSession:
    """Start the simulated bench and open its drivers, or open a real bench (module notes); ``stack`` closes
    everything.

    Parameters
    ----------
    mount : HexapodPose, optional
        The unknown mount error (default: drawn from ``[align.simulator]``; simulated bench only).
    as_built_seed : int, optional
        Overrides ``[tma.as_built] seed`` (simulated bench only).
    noise_waves : float
        Per-pixel white noise of the simulated measurement, waves RMS (simulated bench only).

    Raises
    ------
    InputError
        A real bench without ``[align] station``.
    """
    if not config.align.simulated:
        return open_real_session(config, stack)
    from wavestack.simulated import start_align_bench, unknown_mount  # the simulator starter, simulated bench only

    mount = mount or unknown_mount(config)
    bench = start_align_bench(config, stack, mount=mount, as_built_seed=as_built_seed, noise_waves=noise_waves)
    hexapod = _driver(config.hexapod, stack, f"tcp://127.0.0.1:{bench.hexapod.port}")
    stage = _driver(config.field_stage, stack, f"tcp://127.0.0.1:{bench.field_stage.port}")
    design = TmaModel(config.design)
    station_path = config.station_path()
    station = None
    method = config.align.fit_method
    if station_path is None:
        fitter = TermFitter(design.pupil_mask, config.align.max_noll, method=method)
    else:  # the station's detected aperture loses rim pixels: both fits on the pupil less edge_px
        check_fringes(config, design)
        mask = fixed_aperture(design.pupil_mask, config.align.edge_px)
        fitter = TermFitter(mask, config.align.max_noll, method=method)
        station = _coupled_station(config, station_path, bench, mask, stack)
    logger.info("align: simulated bench, mount error %s (unknown to the loop)", mount.as_tuple())
    return AlignSession(bench, hexapod, stage, design, fitter, _field_positions(config), station)


def _coupled_station(config: AlignConfig, station_path: Path, bench: Any, mask: NDArray[np.bool_],
                     stack: ExitStack) -> StationSource:
    """The simulated station with the telescope coupled to its optic (the reference's tilt added back)."""
    from wavestack.simulated import reference_tilt_step  # the simulator starter, simulated bench only

    service = open_station_service(station_path, stack)
    optic = getattr(service.devices.bench, "optic", None)
    reflection = getattr(getattr(service.config.optic, "surface", None), "reflection_factor", 2.0)
    prepare = reference_tilt_step(config, bench, getattr(optic, "surface", None),
                                  service.config.station.wavelength_nm, reflection)
    return StationSource(service, mask, averaged=config.align.averaged, settle_s=config.align.settle_s,
                         timeout_s=config.align.measure_timeout_s, prepare=prepare)
