"""Rules across a station's tables: settings that each validate alone but can never work together.

Every rule raises one :class:`~wavestack.config.schema.ConfigError` line naming the file, the
tables and keys involved, their values and what was expected:

- the piezo voltage of every phase step, ``bias_v + volts_per_radian * step``, lies inside
  ``[software_min_v, software_max_v]`` and, for a simulated controller, below its ``vlimit_v``
  (a real controller's front-panel limit is read at open: the driver refuses beyond it);
- a set of ``n`` steps fits the set timeout: ``frame_timeout_s > n * settle_s``; and, when
  results go to a PLC, a result can be fresh: ``max_result_age_s > (n - 1) * settle_s`` (a
  result's age runs from its first frame);
- a simulated bench moves the fringes: ``[bench] axis`` is ``[pzt] phase_axis`` and
  ``radians_per_volt`` is nonzero;
- a simulated camera's ``[camera] pixel_format`` (when set) is ``[camera.simulator]
  pixel_format``, whose bit depth is ``[optic] bit_depth``;
- a free-running simulated camera delivers a frame within both timeouts: ``[camera] timeout_s``
  and ``[station] frame_timeout_s`` exceed ``1 / frame_rate_hz``;
- the frames a simulated camera's rings hold, ``(ring_capacity + set_ring_capacity x frames per
  set) x width x height x bytes per pixel``, fit in :data:`MAX_RING_BYTES`;
- a simulated Shack-Hartmann camera's frame holds every ``[shack_hartmann]`` lenslet window;
- ``[outputs]``: ``max_step_nm <= max_removal_nm``; ``first_term`` is at most the modes measured
  and the PLC command block's terms; a simulated PLC accepts ``max_removal_nm``.
"""

from __future__ import annotations

import math
from typing import Final
from wavestack.config._checks import BIT_DEPTH
from wavestack.config.schema import ConfigError
from wavestack.pipeline.instrument import configured_lattice
from wavestack.config.station_schema import StationConfig

__all__ = ["MAX_RING_BYTES", "check_station_rules"]

#: Most memory the frame rings of a simulated camera may hold, bytes (2 GiB).
MAX_RING_BYTES: Final = 2 << 30


def check_station_rules(config: StationConfig) -> None:
    """Apply every rule of the module notes to a parsed station (raises :class:`ConfigError`)."""
    if config.phase_stepping:
        _check_phase_step_voltages(config)
        _check_set_timeout(config)
        if config.camera.simulated:
            _check_bench(config)
    if config.camera.simulated:
        _check_pixel_format(config)
        _check_simulated_frames(config)
    _check_outputs(config)


def _check_phase_step_voltages(config: StationConfig) -> None:
    pzt, source = config.pzt, config.source
    assert pzt is not None
    lower, upper = pzt.software_min_v, pzt.software_max_v
    limit = "[pzt] software_min_v..software_max_v"
    if pzt.url.startswith("sim://") and config.pzt_simulator is not None \
            and config.pzt_simulator.vlimit_v < upper:
        upper, limit = config.pzt_simulator.vlimit_v, "[pzt] software_min_v..[pzt.simulator] vlimit_v"
    for index, step_deg in enumerate(config.processing.steps_deg):
        volts = pzt.bias_v + pzt.volts_per_radian * math.radians(step_deg)
        if not lower <= volts <= upper:
            raise ConfigError(
                f"{source}: [processing] steps_deg[{index}] = {step_deg:g} deg needs {volts:.4g} V on the piezo "
                f"([pzt] bias_v {pzt.bias_v:g} + volts_per_radian {pzt.volts_per_radian:g} x "
                f"{math.radians(step_deg):.4g} rad); expected every step inside {limit} = [{lower:g}, {upper:g}] V")


def _check_set_timeout(config: StationConfig) -> None:
    pzt, station = config.pzt, config.station
    assert pzt is not None
    frames = config.processing.frames_per_set
    if not station.frame_timeout_s > frames * pzt.settle_s:
        raise ConfigError(
            f"{config.source}: [station] frame_timeout_s = {station.frame_timeout_s:g} s: expected more than "
            f"{frames} steps x [pzt] settle_s {pzt.settle_s:g} s = {frames * pzt.settle_s:g} s "
            "(every set would time out)")
    span_s = (frames - 1) * pzt.settle_s
    if config.plc is not None and config.outputs.enabled and not station.max_result_age_s > span_s:
        raise ConfigError(
            f"{config.source}: [station] max_result_age_s = {station.max_result_age_s:g} s: expected more than "
            f"({frames} - 1) steps x [pzt] settle_s {pzt.settle_s:g} s = {span_s:g} s, the age of a result "
            "when its last frame arrives (every result would be stale and none sent)")


def _check_bench(config: StationConfig) -> None:
    pzt, bench = config.pzt, config.bench
    assert pzt is not None
    if bench.axis != pzt.phase_axis:
        raise ConfigError(f"{config.source}: [bench] axis = {bench.axis!r}: expected [pzt] phase_axis "
                          f"{pzt.phase_axis!r} (the simulated fringes would never move)")
    if bench.radians_per_volt == 0.0:
        raise ConfigError(f"{config.source}: [bench] radians_per_volt = 0: expected a nonzero coupling "
                          "(the simulated fringes would never move)")


def _check_pixel_format(config: StationConfig) -> None:
    camera, simulator, source = config.camera, config.camera_simulator, config.source
    if camera.pixel_format is not None and camera.pixel_format != simulator.pixel_format:
        raise ConfigError(f"{source}: [camera] pixel_format = {camera.pixel_format!r}: expected the simulated "
                          f"camera's [camera.simulator] pixel_format {simulator.pixel_format!r}")
    depth = BIT_DEPTH[simulator.pixel_format]
    if config.optic is not None and config.optic.bit_depth != depth:
        raise ConfigError(f"{source}: [optic] bit_depth = {config.optic.bit_depth}: expected {depth}, the bit depth "
                          f"of [camera.simulator] pixel_format {simulator.pixel_format!r}")


def _check_simulated_frames(config: StationConfig) -> None:
    camera, simulator, source = config.camera, config.camera_simulator, config.source
    period_s = 1.0 / simulator.frame_rate_hz
    if not config.phase_stepping:  # free running: a frame every period
        for key, timeout_s in (("[camera] timeout_s", camera.timeout_s),
                               ("[station] frame_timeout_s", config.station.frame_timeout_s)):
            if not timeout_s > period_s:
                raise ConfigError(f"{source}: {key} = {timeout_s:g} s: expected more than the frame period "
                                  f"{period_s:g} s of [camera.simulator] frame_rate_hz {simulator.frame_rate_hz:g}")
    frames = camera.ring_capacity + config.station.set_ring_capacity * config.processing.frames_per_set
    frame_bytes = simulator.width * simulator.height * (1 if BIT_DEPTH[simulator.pixel_format] <= 8 else 2)
    if frames * frame_bytes > MAX_RING_BYTES:
        raise ConfigError(
            f"{source}: [camera] ring_capacity {camera.ring_capacity} + [station] set_ring_capacity "
            f"{config.station.set_ring_capacity} x {config.processing.frames_per_set} frames of [camera.simulator] "
            f"{simulator.width} x {simulator.height} {simulator.pixel_format} hold {frames * frame_bytes / 2**30:.3g} GiB; "
            f"expected at most {MAX_RING_BYTES / 2**30:g} GiB")
    if config.shack_hartmann is not None:
        sensor = config.shack_hartmann
        kind = config.lenslets.lattice if sensor.lattice == "auto" and config.lenslets is not None else sensor.lattice
        shape = (simulator.height, simulator.width)
        try:
            for each in (("square", "hexagonal") if kind == "auto" else (kind,)):
                configured_lattice(sensor.setup(config.station.wavelength_nm), each, shape).check_fits(shape)
        except ValueError as error:
            raise ConfigError(f"{source}: [shack_hartmann] pitch_px, offset_px, grid_shape: {error} "
                              f"([camera.simulator] width {simulator.width}, height {simulator.height})") from None


def _check_outputs(config: StationConfig) -> None:
    outputs, source = config.outputs, config.source
    if outputs.max_step_nm > outputs.max_removal_nm:
        raise ConfigError(f"{source}: [outputs] max_step_nm = {outputs.max_step_nm:g}: expected <= "
                          f"max_removal_nm ({outputs.max_removal_nm:g})")
    modes = config.shack_hartmann.modes if config.shack_hartmann is not None else config.processing.modes
    if outputs.first_term > modes:
        table = "[shack_hartmann]" if config.shack_hartmann is not None else "[processing]"
        raise ConfigError(f"{source}: [outputs] first_term = {outputs.first_term}: expected <= {table} modes "
                          f"({modes}); no measured term would be commanded")
    plc = config.plc
    if plc is None or not outputs.enabled:
        return
    if outputs.first_term > plc.link.n_terms:
        raise ConfigError(f"{source}: [outputs] first_term = {outputs.first_term}: expected <= the {plc.link.n_terms} "
                          f"terms of [plc] command_block {list(plc.link.command_block)}; nothing would be commanded")
    if plc.link.simulated and plc.simulator is not None:
        machine = plc.simulator.polishing.max_removal_nm
        if outputs.max_removal_nm > machine:
            raise ConfigError(f"{source}: [outputs] max_removal_nm = {outputs.max_removal_nm:g}: expected <= the "
                              f"simulated machine's [plc.simulator.polishing] max_removal_nm ({machine:g}), "
                              "which refuses larger commands")
