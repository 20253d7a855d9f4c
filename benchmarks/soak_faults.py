"""The soak's faults: every switch the simulators offer today, a seeded schedule, and the evidence each should leave.

A fault is injected only through a simulator's own switches (``SimulatedU3VCamera.faults`` /
``unplug`` / ``replug``, ``MDT693BDevice.faults``, ``PlcSimulator.faults`` / ``restart``), never by
patching a driver. Each :class:`FaultKind` draws its parameters from a per-fault random generator
(so a seed gives the same schedule and the same parameters), and returns an :class:`Injection`:
timed steps (the last one clears what the fault switched on), and for one-shot switches a probe
that tells whether the simulator has used it.

``expects`` names the signals (see ``soak_report.SIGNALS``) that should show the fault in the
station's results and counters; a fault with no such signal in its window is *unaccounted*.
"""

from __future__ import annotations

import dataclasses
import random
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

__all__ = ["EXTRA_KINDS", "FAULT_KINDS", "FaultKind", "Injection", "ScheduledFault", "Targets", "make_schedule", "select_kinds"]


@dataclass(frozen=True)
class Targets:
    """The simulators of one station incarnation (None when that device is not simulated)."""

    camera: Any
    piezo: Any
    plc: Any


@dataclass
class Injection:
    """What one fault does: ``steps`` are ``(delay_s after the previous step, action)``; the last clears.

    Attributes
    ----------
    params : str
        The drawn parameters, for the report.
    steps : list of (float, callable)
    fired : callable or None
        For a one-shot switch: True once the simulator used it (None: a state switch, always on).
    leftover : callable or None
        Switches a one-shot off if it never fired (before the next fault).
    plc_down_s : float
        How long the PLC's Modbus server is down (s; 0: not a restart).
    plc_reply_delay_s : float
        How late each PLC reply comes while the fault is on (s; 0: not a delay).
    """

    params: str
    steps: list[tuple[float, Callable[[], None]]]
    fired: Callable[[], bool] | None = None
    leftover: Callable[[], None] | None = None
    plc_down_s: float = 0.0
    plc_reply_delay_s: float = 0.0

    @property
    def duration_s(self) -> float:
        """From the first step to the clearing one, s."""
        return sum(delay for delay, _ in self.steps)


@dataclass(frozen=True)
class FaultKind:
    """One kind of fault: its device, what it does, and the signals that should show it."""

    name: str
    device: str
    inject: Callable[[Targets, random.Random], Injection]
    expects: tuple[str, ...] = field(default=())
    what: str = ""


def _noop() -> None:
    return None


def _hold(on: Callable[[], None], off: Callable[[], None], seconds: float, params: str) -> Injection:
    return Injection(params, [(0.0, on), (seconds, off)])


def _setter(obj: Any, name: str, value: Any) -> Callable[[], None]:
    return lambda: setattr(obj, name, value)


# --------------------------------------------------------------------------------------------- camera
def _camera_unplug(low: float, high: float) -> Callable[[Targets, random.Random], Injection]:
    def inject(t: Targets, rng: random.Random) -> Injection:
        seconds = rng.uniform(low, high)
        return _hold(t.camera.unplug, t.camera.replug, seconds, f"{seconds:.2f} s")
    return inject


def _camera_flap(t: Targets, rng: random.Random) -> Injection:
    count, gap = rng.randint(2, 4), rng.uniform(0.1, 0.5)
    steps: list[tuple[float, Callable[[], None]]] = []
    for k in range(count):
        steps += [(0.0 if k == 0 else gap, t.camera.unplug), (gap, t.camera.replug)]
    return Injection(f"{count} x {gap:.2f} s", steps)


def _camera_one_shot(name: str, values: tuple[Any, ...], idle: Any) -> Callable[[Targets, random.Random], Injection]:
    def inject(t: Targets, rng: random.Random) -> Injection:
        faults, value = t.camera.faults, rng.choice(values)
        return Injection(f"{value!r}", [(0.0, _setter(faults, name, value))],
                         fired=lambda: getattr(faults, name) == idle, leftover=_setter(faults, name, idle))
    return inject


def _camera_pending_ack(t: Targets, rng: random.Random) -> Injection:
    ms, seconds = rng.randint(50, 400), rng.uniform(1.0, 3.0)
    faults = t.camera.faults
    return _hold(_setter(faults, "pending_ack_ms", ms), _setter(faults, "pending_ack_ms", 0), seconds,
                 f"{ms} ms for {seconds:.2f} s")


# --------------------------------------------------------------------------------------------- piezo
def _piezo_switch(name: str, low: float, high: float) -> Callable[[Targets, random.Random], Injection]:
    def inject(t: Targets, rng: random.Random) -> Injection:
        seconds = rng.uniform(low, high)
        faults = t.piezo.faults
        return _hold(_setter(faults, name, True), _setter(faults, name, False), seconds, f"{seconds:.2f} s")
    return inject


# --------------------------------------------------------------------------------------------- PLC
def _plc_replies(method: str) -> Callable[[Targets, random.Random], Injection]:
    def inject(t: Targets, rng: random.Random) -> Injection:
        faults, count = t.plc.faults, rng.randint(1, 3)
        options: dict[str, int] = {"keep_bytes": rng.randint(0, 9)} if method == "truncate_replies" else {}
        text = f"{count} replies" + (f", keep {options['keep_bytes']} B" if options else "")
        return Injection(text, [(0.0, lambda: getattr(faults, method)(count, **options))],
                         fired=lambda: faults.pending_reply_faults == 0, leftover=faults.clear)
    return inject


def _plc_delay(t: Targets, rng: random.Random) -> Injection:
    delay, seconds = rng.uniform(0.2, 1.5), rng.uniform(1.0, 4.0)
    faults = t.plc.faults
    held = _hold(_setter(faults, "delay_s", delay), _setter(faults, "delay_s", 0.0), seconds,
                 f"{delay:.2f} s for {seconds:.2f} s")
    return dataclasses.replace(held, plc_reply_delay_s=delay)


def _plc_restart_between(low: float, high: float) -> Callable[[Targets, random.Random], Injection]:
    def inject(t: Targets, rng: random.Random) -> Injection:
        downtime = rng.uniform(low, high)
        return Injection(f"down {downtime:.2f} s", [(0.0, lambda: t.plc.restart(downtime)), (downtime, _noop)],
                         plc_down_s=downtime)
    return inject


def _plc_switch(name: str, low: float, high: float) -> Callable[[Targets, random.Random], Injection]:
    def inject(t: Targets, rng: random.Random) -> Injection:
        seconds = rng.uniform(low, high)
        faults = t.plc.faults
        return _hold(_setter(faults, name, True), _setter(faults, name, False), seconds, f"{seconds:.2f} s")
    return inject


_CORRUPTIONS = ("magic", "block_id", "size")
_FRAME_SIGNALS = ("device_lost", "invalid", "discarded_blocks", "transfer_errors", "frame_gap")
_PLC_SIGNALS = ("heartbeat_errors", "plc_not_sent", "link_reconnects")

FAULT_KINDS: tuple[FaultKind, ...] = (
    FaultKind("camera_unplug_short", "camera", _camera_unplug(0.2, 1.0), ("device_lost",),
              "unplug, replug after 0.2-1 s"),
    FaultKind("camera_unplug_long", "camera", _camera_unplug(3.0, 6.0), ("device_lost",),
              "unplug, replug after 3-6 s"),
    FaultKind("camera_flap", "camera", _camera_flap, ("device_lost",), "2-4 unplug/replug cycles 0.1-0.5 s apart"),
    FaultKind("camera_corrupt_leader", "camera", _camera_one_shot("corrupt_leader", _CORRUPTIONS, None),
              _FRAME_SIGNALS, "next leader damaged (magic, block id or size)"),
    FaultKind("camera_corrupt_trailer", "camera", _camera_one_shot("corrupt_trailer", _CORRUPTIONS, None),
              _FRAME_SIGNALS, "next trailer damaged (magic, block id or size)"),
    FaultKind("camera_partial_payload", "camera", _camera_one_shot("partial_transfer", (True,), False),
              _FRAME_SIGNALS, "next payload transfer cut to half"),
    FaultKind("camera_stall", "camera", _camera_one_shot("stall_next", (True,), False),
              ("stalls_cleared", "device_lost", "invalid"), "stream endpoint stalls (EPIPE until clear_halt)"),
    FaultKind("camera_timeout_reads", "camera", _camera_one_shot("timeout_reads", (1, 2), 0),
              ("stream_timeouts", "device_lost", "invalid"), "next 1-2 stream reads time out"),
    FaultKind("camera_pending_ack", "camera", _camera_pending_ack, (), "PENDING_ACK 50-400 ms for 1-3 s (benign)"),
    FaultKind("piezo_garbage", "piezo", _piezo_switch("garbage", 0.5, 2.0), ("device_lost", "invalid"),
              "replies replaced by random bytes for 0.5-2 s"),
    FaultKind("piezo_silent", "piezo", _piezo_switch("silent", 0.5, 2.0), ("device_lost", "invalid"),
              "controller hung for 0.5-2 s"),
    FaultKind("piezo_split_replies", "piezo", _piezo_switch("split_replies", 1.0, 3.0), (),
              "replies in three pieces for 1-3 s (benign)"),
    FaultKind("piezo_unplug", "piezo", _piezo_switch("unplugged", 0.5, 3.0), ("device_lost", "invalid"),
              "cable out for 0.5-3 s"),
    FaultKind("plc_drop_replies", "plc", _plc_replies("drop_replies"), _PLC_SIGNALS, "next 1-3 replies dropped"),
    FaultKind("plc_truncate_replies", "plc", _plc_replies("truncate_replies"), _PLC_SIGNALS,
              "next 1-3 replies cut to 0-9 bytes"),
    FaultKind("plc_corrupt_replies", "plc", _plc_replies("corrupt_replies"), _PLC_SIGNALS,
              "next 1-3 replies with function code 0x7F"),
    FaultKind("plc_delay", "plc", _plc_delay, (), "every reply 0.2-1.5 s late for 1-4 s (benign below the "
              "link's I/O timeout)"),
    FaultKind("plc_restart", "plc", _plc_restart_between(0.2, 3.0), _PLC_SIGNALS, "Modbus server restart, down 0.2-3 s"),
    FaultKind("plc_freeze_echo", "plc", _plc_switch("freeze_heartbeat_echo", 1.0, 4.0), ("heartbeat_errors",),
              "heartbeat echo frozen for 1-4 s (PLC not scanning)"),
    FaultKind("plc_estop", "plc", _plc_switch("estop", 1.0, 4.0), ("estop_seen", "plc_not_sent"),
              "e-stop pressed for 1-4 s"),
)
# chosen by name only (never in the default mix, so a seed's schedule stays what it was)
EXTRA_KINDS: tuple[FaultKind, ...] = (
    FaultKind("plc_outage", "plc", _plc_restart_between(2.6, 3.0), _PLC_SIGNALS,
              "Modbus server restart, down 2.6-3 s (longer than the watchdog: a fail-safe trip)"),
)


def select_kinds(spec: str | None, targets_present: set[str] | None = None) -> tuple[FaultKind, ...]:
    """The kinds named in a comma list (names or device prefixes ``camera``, ``piezo``, ``plc``); all if None.

    Raises
    ------
    ValueError
        A name that is neither a fault kind nor a device.
    """
    kinds = FAULT_KINDS
    if spec:
        wanted = [part.strip() for part in spec.split(",") if part.strip()]
        known = {k.name for k in FAULT_KINDS + EXTRA_KINDS} | {k.device for k in FAULT_KINDS}
        unknown = [w for w in wanted if w not in known]
        if unknown:
            raise ValueError(f"--faults: unknown fault kind(s) {unknown}; expected names from --list-faults "
                             f"or one of camera, piezo, plc")
        kinds = tuple(k for k in FAULT_KINDS if k.name in wanted or k.device in wanted) + \
            tuple(k for k in EXTRA_KINDS if k.name in wanted)
    if targets_present is not None:
        kinds = tuple(k for k in kinds if k.device in targets_present)
    return kinds


@dataclass(frozen=True)
class ScheduledFault:
    """The ``index``-th fault: ``kind`` at ``t_s`` after the start, with its own seed for the parameters."""

    index: int
    t_s: float
    kind: FaultKind
    seed: str


def make_schedule(seed: int, duration_s: float, every_s: float, kinds: tuple[FaultKind, ...]) -> list[ScheduledFault]:
    """A fault every ``every_s`` (+-25 %, seeded), kinds drawn uniformly, none in the last ``every_s``.

    Examples
    --------
    >>> a = make_schedule(1, 60.0, 10.0, FAULT_KINDS)
    >>> a == make_schedule(1, 60.0, 10.0, FAULT_KINDS) and len(a) == 5
    True
    """
    if every_s <= 0 or not kinds:
        return []
    rng = random.Random(seed)
    schedule: list[ScheduledFault] = []
    t = every_s
    while t <= duration_s - every_s:
        jitter = rng.uniform(-0.25, 0.25) * every_s
        schedule.append(ScheduledFault(len(schedule), t + jitter, rng.choice(kinds), f"{seed}-{len(schedule)}"))
        t += every_s
    return schedule
