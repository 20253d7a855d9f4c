"""The simulated PI GCS 2.0 controller (C-887 class): state and commands, bytes in, answers out.

Written from PI's documents, not from wavestack's driver (see :mod:`.framing` for the wire rules,
:mod:`.codes` for the error numbers, :mod:`.pose` for the pose convention). Behaviour modelled:

* ``ERR?`` answers the last error code and clears it (0 = none): only the last error is kept.
  A failing command changes nothing; a failing query sends no answer at all (the host learns why
  from ``ERR?``), as PI's host library expects (it reads ``ERR?`` after a silent query).
* ``*IDN?`` the configured line; ``CSV?`` ``2.0``; ``SAI?`` / ``SAI? ALL`` the axes, one per line;
  ``HLP?`` the command list (a header line, one line per command, an end line).
* ``POS?`` ``MOV?`` ``ONT?`` ``SVO?`` ``FRF?`` ``TMN?`` ``TMX?`` [axes]: ``AXIS=value`` lines, all
  axes without arguments; an unknown axis sets error 15 (``PI_CNTR_INVALID_AXIS_IDENTIFIER``).
* ``MOV {axis value}``: refused whole, nothing moves, on a syntax error (1), an unknown axis (15),
  an axis named twice (22), an unreferenced axis or one with servo off (5) or a target outside
  ``TMN``/``TMX`` (7); else every axis heads for its target at the system velocity (:mod:`.motion`).
* ``HLT [axes]``, ``STP``, ``#24``: stop (the named axes, or all) where they are and set error 10
  (``PI_CNTR_STOP``); a stopped reference move leaves the axes unreferenced.
* ``SVO {axis 0|1}``: servo off stops that axis; ``FRF [axes]``: a reference move of all axes
  (a hexapod's struts are referenced together) to the zero position, ``#7`` answering busy
  (0xB0) until it ends, ready (0xB1) otherwise (``#7`` says nothing of motion: use ``#5``).
* ``#5``: the moving axes as a hexadecimal bit mask, bit i = axis i (``0`` when all are still).
* ``SPI {R|S|T value}`` / ``SPI?``: the pivot point, settable only while U, V and W are all 0
  (else error 9, ``PI_CNTR_SET_PIVOT_NOT_POSSIBLE``) and within +-``pivot_limit_mm`` (else
  error 17, ``PI_CNTR_PARAM_OUT_OF_RANGE``); a stage without a pivot does not know SPI.
* ``VLS value`` / ``VLS?``: the system velocity; outside (0, max] error 8.
* The command mnemonic is not case-sensitive (GCS 2.0 syntax); axis identifiers are matched as
  written. Unknown commands set error 2, wrong argument counts 24, malformed values 1.
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections import deque
from collections.abc import Callable

from wavestack.simulators.pi_gcs import codes
from wavestack.simulators.pi_gcs.faults import GcsSimFaults
from wavestack.simulators.pi_gcs.framing import Delivery, LineAssembler, deliver, format_reply
from wavestack.simulators.pi_gcs.motion import Segment, hold, plan_segment
from wavestack.simulators.pi_gcs.pose import SimPose
from wavestack.simulators.pi_gcs.settings import HexapodSimSettings

__all__ = ["COMMAND_HISTORY", "GcsController"]

#: Command lines kept in :attr:`GcsController.commands` (the newest).
COMMAND_HISTORY = 10_000
_PIVOT_AXES = ("R", "S", "T")
_ROTATIONS = ("U", "V", "W")
_AXIS_QUERIES = ("POS?", "MOV?", "ONT?", "SVO?", "FRF?", "TMN?", "TMX?")
_SEPARATORS = re.compile(r"[ \t]+")
_DECIMAL = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


class _Refused(Exception):
    """A command the controller refuses with a GCS error code."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


def _number(text: str) -> float:
    """A decimal number as GCS writes them (no inf, nan, hex or digit separators); else error 1."""
    if not _DECIMAL.match(text):
        raise _Refused(codes.PARAM_SYNTAX)
    value = float(text)
    if not math.isfinite(value):  # 1e999
        raise _Refused(codes.PARAM_SYNTAX)
    return value


def _pairs(args: list[str]) -> list[tuple[str, str]]:
    if not args or len(args) % 2:
        raise _Refused(codes.PARAM_SYNTAX)
    names = args[0::2]
    if len(set(names)) != len(names):
        raise _Refused(codes.DOUBLE_AXIS)
    return list(zip(names, args[1::2]))


class GcsController:
    """One simulated controller. Thread-safe: the server's thread feeds it, tests read its state.

    Parameters
    ----------
    settings
        Axes, limits, velocity, pivot, identity, power-on states.
    clock
        Monotonic clock, s (tests pass their own to move time by hand).

    Attributes
    ----------
    faults
        :class:`~wavestack.simulators.pi_gcs.faults.GcsSimFaults` of this controller.

    Examples
    --------
    >>> controller = GcsController(HexapodSimSettings(axes=("X", "Y"), low_limits=(-5.0, -5.0),
    ...                                              high_limits=(5.0, 5.0), pivot=None))
    >>> assembler = LineAssembler()
    >>> [controller.handle(event) for event in assembler.feed(b"MOV X 9\\nERR?\\nERR?\\n")][1:]
    [Delivery(pieces=((0.0, b'7\\n'),), close=False), Delivery(pieces=((0.0, b'0\\n'),), close=False)]
    """

    def __init__(self, settings: HexapodSimSettings, *, clock: Callable[[], float] = time.monotonic) -> None:
        self.settings = settings
        self.faults = GcsSimFaults()
        self._clock = clock
        self._lock = threading.Lock()
        self._axes = settings.axes
        self._segment: Segment = hold(settings.initial_position or (), clock())
        self._velocity = settings.velocity
        self._pivot = settings.pivot
        self._error = codes.NO_ERROR
        self._servo = [settings.servo] * len(self._axes)
        self._referenced = settings.referenced
        self._referencing_until: float | None = None
        self._commands: deque[str] = deque(maxlen=COMMAND_HISTORY)
        self.commands_received = 0
        self._handlers: dict[str, Callable[[list[str], float], list[str] | None]] = {
            "*IDN?": self._idn, "CSV?": self._csv, "ERR?": self._err, "SAI?": self._sai, "HLP?": self._hlp,
            "MOV": self._mov, "HLT": self._hlt, "STP": self._stp, "SVO": self._svo, "FRF": self._frf,
            "SPI": self._spi, "SPI?": self._spi_query, "VLS": self._vls, "VLS?": self._vls_query,
            "#5": self._motion_status, "#7": self._ready, "#24": self._stp,
            **{query: self._axis_query(query) for query in _AXIS_QUERIES}}

    # ------------------------------------------------------------------ ground truth for tests
    @property
    def pose(self) -> SimPose:
        """Every axis's position now (mm, deg)."""
        with self._lock:
            return SimPose(self._axes, self._segment.position(self._now()))

    @property
    def targets(self) -> SimPose:
        """Every axis's present target."""
        with self._lock:
            return SimPose(self._axes, self._segment.target)

    @property
    def pivot(self) -> tuple[float, float, float] | None:
        """The pivot point (R, S, T), mm, or None for a stage without one."""
        with self._lock:
            return self._pivot

    @property
    def velocity(self) -> float:
        """The system velocity (``VLS``), units/s."""
        with self._lock:
            return self._velocity

    @property
    def last_error(self) -> int:
        """The pending error code, without clearing it (``ERR?`` clears)."""
        with self._lock:
            return self._error

    @property
    def referenced(self) -> bool:
        """True once a reference move has ended (or at power-on if so configured)."""
        with self._lock:
            self._now()
            return self._referenced

    @property
    def commands(self) -> tuple[str, ...]:
        """The newest command lines and single-byte commands received, in order."""
        with self._lock:
            return tuple(self._commands)

    # ------------------------------------------------------------------ the wire
    def handle(self, event: tuple[str, str]) -> Delivery:
        """Answer one event of :class:`~wavestack.simulators.pi_gcs.framing.LineAssembler`."""
        kind, text = event
        with self._lock:
            now = self._now()
            self._commands.append(text)
            self.commands_received += 1
            if kind == "too_long":
                self._error = codes.COMMAND_TOO_LONG
                return Delivery()
            words = [text] if kind == "single" else [w for w in _SEPARATORS.split(text.strip(" \t\r")) if w]
            if not words:
                return Delivery()
            mnemonic, args = words[0].upper(), words[1:]
            fault = self.faults.take(mnemonic, ("fail", "drop"))
            if fault is not None and fault.kind == "drop":
                return Delivery(close=True)
            if fault is not None:
                self._error = fault.code
                return Delivery()
            lines = self._execute(mnemonic, args, now)
            if lines is None:
                return Delivery()
            reply = (lines[0].encode("latin-1") if mnemonic == "#7" else format_reply(lines))
            return deliver(reply, self.faults.take(mnemonic, ("split", "truncate")))

    def _execute(self, mnemonic: str, args: list[str], now: float) -> list[str] | None:
        handler = self._handlers.get(mnemonic)
        try:
            if handler is None:
                raise _Refused(codes.UNKNOWN_COMMAND)
            return handler(args, now)
        except _Refused as refusal:
            self._error = refusal.code
            return None

    # ------------------------------------------------------------------ state helpers (lock held)
    def _now(self) -> float:
        now = self._clock()
        if self._referencing_until is not None and now >= self._referencing_until:
            self._referencing_until = None
            self._referenced = True
        return now

    def _index(self, axis: str) -> int:
        try:
            return self._axes.index(axis)
        except ValueError:
            raise _Refused(codes.INVALID_AXIS_IDENTIFIER) from None

    def _axis_indices(self, args: list[str]) -> list[int]:
        return [self._index(a) for a in args] if args else list(range(len(self._axes)))

    def _stop(self, indices: list[int], now: float) -> None:
        """Stop the given axes where they are; the others keep heading for their targets."""
        current = self._segment.position(now)
        target = tuple(current[i] if i in indices else t for i, t in enumerate(self._segment.target))
        self._segment = plan_segment(current, target, now=now, velocity=self._velocity,
                                     slow_factor=self.faults.slow_factor, stuck=self._segment.stuck)
        if self._referencing_until is not None:
            self._referencing_until = None
            self._referenced = False
        self._error = codes.STOP

    # ------------------------------------------------------------------ commands
    @staticmethod
    def _no_args(args: list[str]) -> None:
        if args:
            raise _Refused(codes.PARAM_NR)

    def _idn(self, args: list[str], now: float) -> list[str]:
        self._no_args(args)
        return [self.settings.idn]

    def _csv(self, args: list[str], now: float) -> list[str]:
        self._no_args(args)
        return ["2.0"]

    def _err(self, args: list[str], now: float) -> list[str]:
        self._no_args(args)
        code, self._error = self._error, codes.NO_ERROR
        return [str(code)]

    def _sai(self, args: list[str], now: float) -> list[str]:
        if args and [a.upper() for a in args] != ["ALL"]:
            raise _Refused(codes.PARAM_SYNTAX)
        return list(self._axes)

    def _hlp(self, args: list[str], now: float) -> list[str]:
        self._no_args(args)
        names = sorted(name for name in self._handlers if not name.startswith("#"))
        if self._pivot is None:
            names = [name for name in names if not name.startswith("SPI")]
        return ["The following commands are available:", *names, "end of help"]

    def _axis_query(self, mnemonic: str) -> Callable[[list[str], float], list[str]]:
        return lambda args, now: self._format_axes(mnemonic, args, now)

    def _format_axes(self, mnemonic: str, args: list[str], now: float) -> list[str]:
        indices = self._axis_indices(args)
        moving = self._segment.moving(now)
        referencing = self._referencing_until is not None
        values = {
            "POS?": lambda i: f"{self._segment.position(now)[i]:.9f}",
            "MOV?": lambda i: f"{self._segment.target[i]:.9f}",
            "ONT?": lambda i: "0" if moving[i] or referencing else "1",
            "SVO?": lambda i: "1" if self._servo[i] else "0",
            "FRF?": lambda i: "1" if self._referenced else "0",
            "TMN?": lambda i: f"{self.settings.low_limits[i]:.9f}",
            "TMX?": lambda i: f"{self.settings.high_limits[i]:.9f}",
        }[mnemonic]
        return [f"{self._axes[i]}={values(i)}" for i in indices]

    def _mov(self, args: list[str], now: float) -> None:
        pairs = [(self._index(axis), _number(value)) for axis, value in _pairs(args)]
        if not self._referenced or any(not self._servo[i] for i, _ in pairs):
            raise _Refused(codes.MOVE_WITHOUT_REF_OR_NO_SERVO)
        lows, highs = self.settings.low_limits, self.settings.high_limits
        if any(not lows[i] <= value <= highs[i] for i, value in pairs):
            raise _Refused(codes.POS_OUT_OF_LIMITS)
        target = list(self._segment.target)
        for i, value in pairs:
            target[i] = value
        stuck = frozenset(self._axes.index(a) for a in self.faults.stuck_axes if a in self._axes)
        self._segment = plan_segment(self._segment.position(now), tuple(target), now=now, velocity=self._velocity,
                                     slow_factor=self.faults.slow_factor, stuck=stuck)
        return None

    def _hlt(self, args: list[str], now: float) -> None:
        self._stop(self._axis_indices(args), now)
        return None

    def _stp(self, args: list[str], now: float) -> None:
        self._no_args(args)
        self._stop(list(range(len(self._axes))), now)
        return None

    def _svo(self, args: list[str], now: float) -> None:
        pairs = [(self._index(axis), state) for axis, state in _pairs(args)]
        if any(state not in ("0", "1") for _, state in pairs):
            raise _Refused(codes.PARAM_SYNTAX)
        switched_off = [i for i, state in pairs if state == "0" and self._servo[i]]
        for i, state in pairs:
            self._servo[i] = state == "1"
        if switched_off:
            error = self._error
            self._stop(switched_off, now)
            self._error = error  # switching the servo off is not a stop by command
        return None

    def _frf(self, args: list[str], now: float) -> None:
        self._axis_indices(args)
        if not all(self._servo):
            raise _Refused(codes.MOVE_WITHOUT_REF_OR_NO_SERVO)
        home = tuple(min(max(0.0, lo), hi) for lo, hi in zip(self.settings.low_limits, self.settings.high_limits))
        segment = plan_segment(self._segment.position(now), home, now=now, velocity=self._velocity,
                               slow_factor=self.faults.slow_factor)
        self._segment = segment
        self._referenced = False
        self._referencing_until = now + max(segment.duration_s, self.settings.reference_time_s)
        return None

    def _spi(self, args: list[str], now: float) -> None:
        if self._pivot is None:
            raise _Refused(codes.UNKNOWN_COMMAND)
        pairs = _pairs(args)
        if any(name not in _PIVOT_AXES for name, _ in pairs):
            raise _Refused(codes.INVALID_AXIS_IDENTIFIER)
        values = {name: _number(value) for name, value in pairs}
        if any(abs(v) > self.settings.pivot_limit_mm for v in values.values()):
            raise _Refused(codes.PARAM_OUT_OF_RANGE)
        position, target = self._segment.position(now), self._segment.target
        rotations = [i for i, a in enumerate(self._axes) if a in _ROTATIONS]
        if any(position[i] != 0.0 or target[i] != 0.0 for i in rotations):
            raise _Refused(codes.SET_PIVOT_NOT_POSSIBLE)
        pivot = dict(zip(_PIVOT_AXES, self._pivot))
        pivot.update(values)
        self._pivot = (pivot["R"], pivot["S"], pivot["T"])
        return None

    def _spi_query(self, args: list[str], now: float) -> list[str]:
        if self._pivot is None:
            raise _Refused(codes.UNKNOWN_COMMAND)
        if any(name not in _PIVOT_AXES for name in args):
            raise _Refused(codes.INVALID_AXIS_IDENTIFIER)
        pivot = dict(zip(_PIVOT_AXES, self._pivot))
        return [f"{name}={pivot[name]:.9f}" for name in (args or _PIVOT_AXES)]

    def _vls(self, args: list[str], now: float) -> None:
        if len(args) != 1:
            raise _Refused(codes.PARAM_NR)
        velocity = _number(args[0])
        if not 0.0 < velocity <= self.settings.max_velocity:
            raise _Refused(codes.VEL_OUT_OF_LIMITS)
        self._velocity = velocity
        return None

    def _vls_query(self, args: list[str], now: float) -> list[str]:
        self._no_args(args)
        return [f"{self._velocity:.9f}"]

    def _motion_status(self, args: list[str], now: float) -> list[str]:
        moving = self._segment.moving(now)
        referencing = self._referencing_until is not None
        mask = sum(1 << i for i, m in enumerate(moving) if m or referencing)
        return [f"{mask:X}"]

    def _ready(self, args: list[str], now: float) -> list[str]:
        return ["\xb0\n" if self._referencing_until is not None else "\xb1\n"]
