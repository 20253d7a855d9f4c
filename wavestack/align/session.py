"""An alignment session: the bench's devices opened and the loop's pieces built from the configuration.

:func:`open_session` starts the simulated bench (``[align] simulated = true``: both PI simulators on
loopback, the as-built telescope with a seeded mount error, :mod:`wavestack.simulators.align_bench`),
opens the hexapod and field-stage drivers on them, and builds what :class:`~.loop.AlignmentLoop`
takes: the design model, the fitter on the pupil's aperture, the field stage's target per field
point and the measurement (the bench's wavefront maps, or with ``[align] station`` the station's
maps through the simulated camera, :mod:`.station_source`). A real
bench (``simulated = false``) needs an interferometer source wired here: not done yet (the
session refuses it with a message).
"""

from __future__ import annotations

import logging
from contextlib import ExitStack
from dataclasses import dataclass, replace

import numpy as np

from wavestack.align.fringes import MAX_SLOPE_WAVES_PER_PX, fringe_slope_bound
from wavestack.align.loop import AlignOptions, FieldMeasurement
from wavestack.align.station_source import StationSource, fixed_aperture
from wavestack.align.terms import TermFitter
from wavestack.config.align import AlignConfig
from wavestack.config.hexapod import build_hexapod
from wavestack.drivers.pi_gcs import PIHexapod
from wavestack.pipeline import InputError
from wavestack.simulators.align_bench import AlignmentBench, draw_mount
from wavestack.simulators.tma import HexapodPose, TmaModel

logger = logging.getLogger(__name__)

__all__ = ["AlignSession", "check_fringes", "open_session", "options_of"]


@dataclass(eq=False)
class AlignSession:
    """What an alignment runs on (the loop's keyword arguments, and the bench for tests)."""

    bench: AlignmentBench
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


def _driver(settings, port: int, stack: ExitStack) -> PIHexapod:  # type: ignore[no-untyped-def]
    driver = build_hexapod(replace(settings, url=f"tcp://127.0.0.1:{port}"))
    driver.open()
    stack.callback(driver.close)
    return driver


def open_session(config: AlignConfig, stack: ExitStack, *, mount: HexapodPose | None = None,
                 as_built_seed: int | None = None, noise_waves: float = 0.0) -> AlignSession:
    """Start the simulated bench and open its drivers (module notes); ``stack`` closes everything.

    Parameters
    ----------
    mount : HexapodPose, optional
        The unknown mount error (default: drawn from ``[align.simulator]``).
    as_built_seed : int, optional
        Overrides ``[tma.as_built] seed``.
    noise_waves : float
        Per-pixel white noise of the simulated measurement, waves RMS.

    Raises
    ------
    InputError
        ``[align] simulated = false`` (no real interferometer source yet).
    """
    if not config.align.simulated:
        raise InputError(f"{config.source}: [align] simulated = false: a real interferometer source is not wired "
                         "into the alignment loop yet; set simulated = true")
    sim = config.align.simulator
    mount = mount or draw_mount(sim.decentre_mm, sim.despace_mm, sim.tilt_deg, sim.seed)
    errors = config.as_built if as_built_seed is None else replace(config.as_built, seed=as_built_seed)
    bench = AlignmentBench(config.design, errors, mount, hexapod=config.hexapod_simulator,
                           field_stage=config.field_stage_simulator, mm_per_deg=config.align.field_stage_mm_per_deg,
                           noise_waves=noise_waves, seed=sim.seed)
    stack.enter_context(bench)
    hexapod = _driver(config.hexapod, bench.hexapod.port, stack)
    stage = _driver(config.field_stage, bench.field_stage.port, stack)
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
        station = StationSource(station_path, bench, mask, stack, averaged=config.align.averaged,
                                null_tilt=config.align.null_tilt)
    scale = config.align.field_stage_mm_per_deg
    positions = [dict(zip(config.field_stage.axes, (fx * scale, fy * scale)))
                 for fx, fy in config.design.field_points_deg]
    logger.info("align: simulated bench, mount error %s (unknown to the loop)", mount.as_tuple())
    return AlignSession(bench, hexapod, stage, design, fitter, positions, station)
