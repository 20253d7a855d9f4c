"""An in-memory alignment bench for many seeded trials: the loop's real code, platforms without sockets.

:func:`run_trial` runs the loop on the model's maps; :func:`camera_trial` runs the default session
(the GCS simulators, the station's camera and the CSF-QCM fitter) and records the moves sent.
The platforms keep the driver's contract the loop uses (position, move_absolute refusing a step
or a target outside the limits, wait_on_target, stop_all, limits) and record every move, so the
trials also check that no move the loop sends breaks the limits. The end-to-end path (the GCS
drivers and simulators) is test_convergence.py's single trial.
"""

from __future__ import annotations

import threading
import time
from contextlib import ExitStack

import numpy as np

from wavestack.align import TermFitter
from wavestack.align.loop import AlignmentLoop, AlignOptions, AlignSummary, FieldMeasurement
from wavestack.align.session import open_session, options_of
from wavestack.drivers.pi_gcs import HexapodLimits, move_refusals
from wavestack.simulators.align_bench import draw_mount
from wavestack.pipeline.telescope import HexapodPose, TmaModel

LIMITS = HexapodLimits(soft={"X": (-5.0, 5.0), "Y": (-5.0, 5.0), "Z": (-2.0, 2.0), "U": (-0.5, 0.5),
                             "V": (-0.5, 0.5), "W": (-0.5, 0.5)},
                       max_step={"X": 0.5, "Y": 0.5, "Z": 0.5, "U": 0.05, "V": 0.05, "W": 0.05})
STAGE = HexapodLimits.uniform(("1", "2"), lower=-25.0, upper=25.0, max_step=50.0)


class MemoryPlatform:
    """A platform that arrives at once (module notes)."""

    def __init__(self, limits: HexapodLimits) -> None:
        self.limits = limits
        self._position = {axis: 0.0 for axis in limits.axes}
        self.moves: list[tuple[dict[str, float], dict[str, float]]] = []
        self.stopped = 0

    def position(self) -> dict[str, float]:
        return dict(self._position)

    def move_absolute(self, pose):  # noqa: ANN001, ANN201 - the driver's signature
        refusals = move_refusals(dict(pose), self._position, self.limits, self.limits.soft)
        if refusals:
            raise ValueError("; ".join(refusals))
        self.moves.append((dict(self._position), dict(pose)))
        self._position.update(pose)

        class _Sent:
            target = dict(pose)
        return _Sent()

    def wait_on_target(self, timeout_s: float) -> dict[str, float]:
        return self.position()

    def stop_all(self) -> None:
        self.stopped += 1


def run_trial(design, as_built, seed: int, options: AlignOptions, *, noise_waves: float = 0.02,
              decentre_mm: float = 0.3, despace_mm: float = 0.3, tilt_deg: float = 0.03,
              fitter: TermFitter | None = None):
    """One seeded trial: (summary, hexapod platform, mount); ``fitter`` default: CSF-QCM on the pupil."""
    mount = draw_mount(decentre_mm, despace_mm, tilt_deg, seed)
    truth = TmaModel(design, as_built, seed=1000 + seed, mount=mount)
    model = TmaModel(design)
    hexapod, stage = MemoryPlatform(LIMITS), MemoryPlatform(STAGE)
    fields = design.field_points_deg
    rng = np.random.default_rng(seed)

    def measure(index: int) -> FieldMeasurement:
        p = hexapod.position()
        waves = truth.wavefront(fields[index], HexapodPose(p["X"], p["Y"], p["Z"], p["U"], p["V"], p["W"]))
        return FieldMeasurement(waves + rng.normal(0.0, noise_waves, waves.shape), time.time_ns())

    loop = AlignmentLoop(design_model=model.wavefront, fields=fields,
                         field_positions=[{"1": 10 * fx, "2": 10 * fy} for fx, fy in fields],
                         fitter=fitter or TermFitter(model.pupil_mask, 22), hexapod=hexapod, field_stage=stage,  # type: ignore[arg-type]
                         measure=measure, options=options, stop=threading.Event())
    summary: AlignSummary = loop.run()
    return summary, hexapod, mount


class RecordingHexapod:
    """A driver whose moves are recorded as ``(position before, target sent)``; everything else delegated."""

    def __init__(self, driver) -> None:  # noqa: ANN001
        self._driver = driver
        self.moves: list[tuple[dict[str, float], dict[str, float]]] = []

    def __getattr__(self, name: str):  # noqa: ANN204
        return getattr(self._driver, name)

    def move_absolute(self, target):  # noqa: ANN001, ANN201 - the driver's signature
        before = self._driver.position()
        sent = self._driver.move_absolute(target)
        self.moves.append((before, dict(sent.target)))
        return sent


def camera_trial(config, seed: int, *, on_event=None):  # noqa: ANN001, ANN201
    """One seeded trial of ``config``'s session (mount drawn from ``[align.simulator]``'s ranges with
    ``seed``, as-built seed ``1000 + seed``): (summary, moves sent, the hexapod's limits)."""
    sim = config.align.simulator
    mount = draw_mount(sim.decentre_mm, sim.despace_mm, sim.tilt_deg, seed)
    with ExitStack() as stack:
        session = open_session(config, stack, mount=mount, as_built_seed=1000 + seed)
        hexapod = RecordingHexapod(session.hexapod)
        arguments = {**session.loop_arguments(), "hexapod": hexapod}
        loop = AlignmentLoop(**arguments, options=options_of(config),  # type: ignore[arg-type]
                             stop=threading.Event(), on_event=on_event)
        summary = loop.run()
        return summary, hexapod.moves, session.hexapod.limits
