"""Start the simulated alignment bench an ``[align] simulated = true`` file describes, and couple it to a station.

The two PI controllers on loopback and the as-built telescope with a seeded mount error of the
aligned mirror that the loop does not know (:class:`~wavestack.simulators.align_bench.AlignmentBench`);
with ``[align] station`` the telescope's wavefront is put on the station's simulated optic before
each measurement, the interferometer's reference tilt set as an operator sets it
(:func:`reference_tilt_step`).
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wavestack.config.align import AlignConfig
from wavestack.pipeline.telescope import HexapodPose
from wavestack.simulated.settings import hexapod_settings
from wavestack.simulators.align_bench import AlignmentBench, SurfaceCoupling, draw_mount

__all__ = ["align_bench", "reference_tilt_step", "start_align_bench", "unknown_mount"]


def unknown_mount(config: AlignConfig, seed: int | None = None) -> HexapodPose:
    """The mount error ``[align.simulator]`` draws (seeded, uniform within its ranges; ``seed`` overrides)."""
    sim = config.align.simulator
    return draw_mount(sim.decentre_mm, sim.despace_mm, sim.tilt_deg, sim.seed if seed is None else seed)


def align_bench(config: AlignConfig, *, mount: HexapodPose | None = None, as_built_seed: int | None = None,
                seed: int | None = None, noise_waves: float = 0.0, host: str = "127.0.0.1", hexapod_port: int = 0,
                field_stage_port: int = 0) -> AlignmentBench:
    """The simulated bench, not started yet (a context manager that starts both controllers).

    Parameters
    ----------
    mount : HexapodPose, optional
        The unknown mount error (default: :func:`unknown_mount` with ``seed``).
    as_built_seed : int, optional
        Overrides ``[tma.as_built] seed``.
    seed : int, optional
        Overrides ``[align.simulator] seed`` (the mount's draw and the renders' noise).
    noise_waves : float
        Per-pixel white noise of the bench's own renders, waves RMS.
    host, hexapod_port, field_stage_port
        Where the controllers listen (default: loopback, free ports).

    Raises
    ------
    ConfigError
        ``[hexapod.simulator]`` or ``[field_stage.simulator]`` values the simulator refuses.
    """
    errors = config.as_built if as_built_seed is None else replace(config.as_built, seed=as_built_seed)
    return AlignmentBench(config.design, errors, mount or unknown_mount(config, seed),
                          hexapod=hexapod_settings(config.hexapod_simulator, source=config.source),
                          field_stage=hexapod_settings(config.field_stage_simulator, source=config.source,
                                                       table="field_stage"),
                          mm_per_deg=config.align.field_stage_mm_per_deg, noise_waves=noise_waves,
                          seed=config.align.simulator.seed if seed is None else seed, host=host,
                          hexapod_port=hexapod_port, field_stage_port=field_stage_port)


def start_align_bench(config: AlignConfig, stack: ExitStack, **options: Any) -> AlignmentBench:
    """:func:`align_bench` started; ``stack`` stops both controllers."""
    bench = align_bench(config, **options)
    stack.enter_context(bench)
    return bench


def reference_tilt_step(config: AlignConfig, bench: AlignmentBench, surface: Any, wavelength_nm: float,
                        reflection_factor: float) -> Callable[[], NDArray[np.float64]]:
    """The step a station measurement takes first on the simulated bench (``StationSource``'s ``prepare``).

    It renders the telescope now, sets the reference's tilt (``[align] null_tilt``), puts the rest
    on the station optic's ``surface`` and returns the tilt set as a map (waves), which the
    measurement adds back.
    """
    coupling = SurfaceCoupling(bench, surface, wavelength_nm, reflection_factor, null_tilt=config.align.null_tilt)

    def prepare() -> NDArray[np.float64]:
        frame, tilt = coupling.refresh()
        return tilt.plane(frame.waves.shape)

    return prepare
