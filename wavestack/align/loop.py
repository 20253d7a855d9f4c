"""The alignment loop: field points -> terms -> estimate -> hexapod -> wait -> verify, until it stops.

:class:`AlignmentLoop` drives :mod:`~wavestack.align.state`'s machine with the loop kernel's runner
(:func:`~wavestack.loop.run_machine`): each phase does its one piece of work and turns what
happened into an event; :func:`~wavestack.align.state.advance` decides where to go. On entering a
fault or a stop the hexapod is halted (``stop_all``, ``#24``) before anything
else; a halt that fails is logged and named in the summary (the platform may still move: the
operator must know). A measurement is refused (UNTRUSTED, no move) when the source raises, when it
was exposed before the hexapod's last arrival (stale), or when it is not finite on the aperture.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wavestack.align.correction import PlannedMove, plan_move
from wavestack.align.estimator import Estimate, estimate_state
from wavestack.align.state import AlignEvent, AlignPhase, AlignState, advance, judge_iteration
from wavestack.align.terms import TermFitter
from wavestack.drivers.errors import DeviceError
from wavestack.drivers.pi_gcs import PIHexapod
from wavestack.loop import EventRecord, Transitions, run_machine
from wavestack.pipeline.telescope import DOFS, WavefrontModel, build_sensitivity

logger = logging.getLogger(__name__)

__all__ = ["AlignOptions", "AlignSummary", "FieldMeasurement", "IterationRecord", "AlignmentLoop"]


@dataclass(frozen=True, eq=False)
class FieldMeasurement:
    """One averaged measurement at a field point: waves (H, W), NaN outside; host exposure time, ns."""

    waves: NDArray[np.float64]
    exposure_ns: int


@dataclass(frozen=True)
class AlignOptions:
    """What the loop runs to (``[align]`` with the command line's overrides)."""

    target_rms_waves: float = 1 / 14
    max_iterations: int = 5
    gain: float = 0.9
    rcond: float = 1e-3
    min_improvement: float = 0.0
    steps: tuple[float, ...] = (0.01, 0.01, 0.01, 0.001, 0.001)
    scales: tuple[float, ...] = (0.1, 0.1, 0.1, 0.01, 0.01)
    readback_tolerance: tuple[float, ...] = (1e-3, 1e-3, 1e-3, 1e-4, 1e-4)
    move_timeout_s: float = 30.0


@dataclass(frozen=True)
class IterationRecord:
    """One iteration as printed and recorded.

    Attributes
    ----------
    iteration : int
        0 for the first measurement.
    rms_waves : tuple of float
        RMS per field point, waves: piston removed (and the plane, on a real bench: ``TermFitter.rms``).
    estimate : tuple of float or None
        Estimated misalignment X Y Z mm, U V deg (None when the loop stopped before estimating).
    move : dict or None
        Target sent per axis.
    read_back : dict or None
        Position read back after the move.
    """

    iteration: int
    rms_waves: tuple[float, ...]
    estimate: tuple[float, ...] | None = None
    move: dict[str, float] | None = None
    read_back: dict[str, float] | None = None

    def to_json(self) -> dict[str, object]:
        return {"type": "iteration", "iteration": self.iteration, "rms_waves": list(self.rms_waves),
                "estimate": dict(zip(DOFS, self.estimate)) if self.estimate else None, "move": self.move,
                "read_back": self.read_back}


@dataclass(frozen=True)
class AlignSummary:
    """How an alignment ended: the terminal state, every iteration, whether the halt succeeded."""

    state: AlignState
    iterations: tuple[IterationRecord, ...] = ()
    halted: bool | None = None

    def to_json(self) -> dict[str, object]:
        return {"type": "summary", "final_phase": self.state.phase.value, "reason": self.state.reason,
                "iterations_done": self.state.iterations_done, "halted": self.halted,
                "worst_rms_waves": [max(r.rms_waves) for r in self.iterations if r.rms_waves]}


@dataclass
class _Run:
    state: AlignState = field(default_factory=AlignState)
    maps: list[FieldMeasurement] = field(default_factory=list)
    previous_worst: float | None = None
    estimate: Estimate | None = None
    move: PlannedMove | None = None
    record: IterationRecord | None = None
    not_before_ns: int = 0
    records: list[IterationRecord] = field(default_factory=list)
    halted: bool | None = None
    # the misalignment at zero pose, last estimated (the state is pose + mount, to first order):
    # the sensitivity is re-linearised at current pose + mount each iteration
    mount: NDArray[np.float64] = field(default_factory=lambda: np.zeros(len(DOFS)))


class AlignmentLoop:
    """One alignment run on a hexapod, a field stage and a measurement source (module notes).

    Parameters
    ----------
    design_model : callable
        ``design_model(field_deg, pose) -> waves (H, W)``: the design telescope.
    fields : sequence of (float, float)
        Field points, deg.
    field_positions : sequence of dict
        The field stage's target per field point.
    fitter : TermFitter
        On the measurement's aperture.
    hexapod, field_stage : PIHexapod
        Opened drivers.
    measure : callable
        ``measure(field_index) -> FieldMeasurement``; any exception is a refused measurement.
    options : AlignOptions
    stop : threading.Event
    recorder : EventRecord, optional
        Records every transition (the alignment record).
    on_iteration, on_event : callable, optional
    """

    def __init__(self, *, design_model: WavefrontModel, fields: Sequence[tuple[float, float]],
                 field_positions: Sequence[dict[str, float]], fitter: TermFitter, hexapod: PIHexapod,
                 field_stage: PIHexapod, measure: Callable[[int], FieldMeasurement], options: AlignOptions,
                 stop: threading.Event, recorder: EventRecord | None = None,
                 on_iteration: Callable[[IterationRecord], None] | None = None,
                 on_event: Callable[[str, str], None] | None = None) -> None:
        if len(field_positions) != len(fields) or not fields:
            raise ValueError(f"field_positions: expected one per field point ({len(fields)}), got {len(field_positions)}")
        self._model, self._fields, self._positions = design_model, [tuple(f) for f in fields], list(field_positions)
        self._fitter, self._hexapod, self._stage, self._measure = fitter, hexapod, field_stage, measure
        self._options, self._stop = options, stop
        self._on_iteration = on_iteration
        self._note = Transitions("align", recorder=recorder, on_event=on_event)

    def run(self) -> AlignSummary:
        """Run to a terminal phase; returns how it ended (never raises a device error)."""
        r = _Run()
        steps = {AlignPhase.MOVING_FIELD: self._move_field, AlignPhase.MEASURING: self._take,
                 AlignPhase.CHECKING: self._check, AlignPhase.ESTIMATING: self._estimate,
                 AlignPhase.MOVING_HEXAPOD: self._send, AlignPhase.WAITING: self._wait,
                 AlignPhase.VERIFYING: self._verify}
        run_machine(r, steps, advance=advance, stop=self._stop, stop_event=AlignEvent.STOP, note=self._note,
                    entered=self._entered)
        if r.record is not None:
            self._emit(r)
        return AlignSummary(r.state, tuple(r.records), r.halted)

    # ------------------------------------------------------------------ helpers
    def _entered(self, r: _Run) -> None:
        """On entering a fault or a stop, halt the hexapod before anything else."""
        if r.state.halt_on_entry:
            r.halted = self._halt()

    def _emit(self, r: _Run) -> None:
        assert r.record is not None
        r.records.append(r.record)
        if self._on_iteration is not None:
            self._on_iteration(r.record)
        r.record = None

    def _halt(self) -> bool:
        """Stop the hexapod (``#24``); after a lost connection reconnect once and stop again."""
        for attempt in range(2):
            try:
                if attempt:
                    self._hexapod.close()
                    self._hexapod.open()
                self._hexapod.stop_all()
                return True
            except (DeviceError, OSError) as error:
                logger.error("align: halting the hexapod failed (attempt %d): %s", attempt + 1, error)
        return False

    # ------------------------------------------------------------------ phases
    def _move_field(self, r: _Run) -> tuple[AlignEvent, str]:
        index = r.state.field_index
        try:
            self._stage.move_absolute(self._positions[index])
            self._stage.wait_on_target(self._options.move_timeout_s)
        except (DeviceError, OSError, ValueError) as error:
            return AlignEvent.FAULT, f"field stage to point {index}: {error}"
        return AlignEvent.FIELD_REACHED, f"field point {index} {self._fields[index]} deg"

    def _take(self, r: _Run) -> tuple[AlignEvent, str]:
        index = r.state.field_index
        if index == 0:
            r.maps = []
        try:
            measured = self._measure(index)
            waves = np.asarray(measured.waves, dtype=np.float64)
            if measured.exposure_ns < r.not_before_ns:
                raise ValueError("stale: exposed before the hexapod's last arrival")
            self._fitter.terms(waves)  # finite on the aperture, right shape
        except Exception as error:  # noqa: BLE001 - any failure of the source refuses the measurement
            return AlignEvent.UNTRUSTED, f"measurement at field point {index} refused: {error}"
        r.maps.append(FieldMeasurement(waves, measured.exposure_ns))
        rms = self._fitter.rms(waves)
        if index + 1 < len(self._fields):
            return AlignEvent.MEASURED, f"field point {index}: RMS {rms:.4f} waves"
        return AlignEvent.ALL_MEASURED, f"field point {index}: RMS {rms:.4f} waves (all measured)"

    def _check(self, r: _Run) -> tuple[AlignEvent, str]:
        rms = tuple(self._fitter.rms(m.waves) for m in r.maps)
        if r.record is not None:
            self._emit(r)
        r.record = IterationRecord(r.state.iterations_done, rms)
        o = self._options
        event, reason = judge_iteration(rms, r.previous_worst, r.state.iterations_done,
                                        target_rms_waves=o.target_rms_waves, max_iterations=o.max_iterations,
                                        min_improvement=o.min_improvement)
        r.previous_worst = max(rms) if rms else None
        return event, reason

    def _estimate(self, r: _Run) -> tuple[AlignEvent, str]:
        o = self._options
        try:
            position = self._hexapod.position()
            current = np.array([position[a] for a in DOFS])
            measured = np.concatenate([self._fitter.terms(m.waves) for m in r.maps])
            at = current + r.mount
            sensitivity = build_sensitivity(self._model, self._fields, self._fitter, at=at,
                                            steps=np.array(o.steps), scales=np.array(o.scales))
            r.estimate = estimate_state(sensitivity, measured, rcond=o.rcond)
            limits = self._hexapod.limits
            r.move = plan_move(position, r.estimate.state, gain=o.gain, max_step=limits.max_step, soft=limits.soft)
        except (DeviceError, OSError, ValueError) as error:
            return AlignEvent.FAULT, f"no correction: {error}"
        r.mount = r.estimate.state - current
        assert r.record is not None
        r.record = IterationRecord(r.record.iteration, r.record.rms_waves, tuple(float(v) for v in r.estimate.state))
        est = " ".join(f"{a}={v:+.4f}" for a, v in zip(DOFS, r.estimate.state))
        return AlignEvent.ESTIMATED, (f"estimate {est} ({r.estimate.kept} singular values, residual "
                                      f"{r.estimate.residual_rms_waves:.4f} waves); step scale {r.move.scale:.3g}"
                                      + (f", clipped {list(r.move.clipped)}" if r.move.clipped else ""))

    def _send(self, r: _Run) -> tuple[AlignEvent, str]:
        assert r.move is not None and r.record is not None
        try:
            sent = self._hexapod.move_absolute(r.move.target)
        except (DeviceError, OSError, ValueError) as error:
            return AlignEvent.FAULT, f"hexapod move refused or failed: {error}"
        r.record = IterationRecord(r.record.iteration, r.record.rms_waves, r.record.estimate, dict(sent.target))
        return AlignEvent.MOVE_SENT, "MOV " + " ".join(f"{a} {v:+.6f}" for a, v in sent.target.items())

    def _wait(self, r: _Run) -> tuple[AlignEvent, str]:
        assert r.record is not None
        try:
            position = self._hexapod.wait_on_target(self._options.move_timeout_s)
        except (DeviceError, OSError) as error:
            return AlignEvent.FAULT, f"hexapod not on target: {error}"
        r.not_before_ns = time.time_ns()
        r.record = IterationRecord(r.record.iteration, r.record.rms_waves, r.record.estimate, r.record.move,
                                   {a: float(v) for a, v in position.items()})
        return AlignEvent.ON_TARGET, "on target"

    def _verify(self, r: _Run) -> tuple[AlignEvent, str]:
        assert r.record is not None and r.record.move is not None and r.record.read_back is not None
        off = {a: r.record.read_back[a] - v for a, v in r.record.move.items()
               if not abs(r.record.read_back[a] - v) <= self._options.readback_tolerance[DOFS.index(a)]}
        if off:
            return AlignEvent.FAULT, f"position read back differs from the move sent by {off}"
        return AlignEvent.VERIFIED, "read-back within tolerance"
