"""Driver for PI hexapod controllers (C-887 class) and PI stages speaking GCS 2.0 ASCII.

:class:`PIHexapod` *has* a :class:`~wavestack.drivers.link.ByteLink`: ``tcp://HOST[:PORT]`` (C-887
controllers listen on port 50000, MS204E [1]_) or a pyserial URL (RS-232 ``/dev/ttyUSB0``, ``COM3``, a
pseudo-terminal, ``socket://``, ``sim://``) at 115200 8N1, the C-887's default RS-232 setting [1]_.
Bytes are encoded and framed by :mod:`~wavestack.drivers.pi_gcs.protocol` (a reply ends at an LF
not preceded by a space); after a timeout or a garbled reply the next exchange first drains late
bytes. Moves are checked
by :mod:`~wavestack.drivers.pi_gcs.limits`. The axes are configuration, not code: the default is a
hexapod's X Y Z (mm) U V W (deg), and the same driver drives a two-axis stage with axes
``("1", "2")`` or ``("X", "Y")``.

On :meth:`PIHexapod.open` the driver clears a stale error (``ERR?``, logged), reads ``*IDN?``,
checks ``CSV?`` is 2.x, reads the axes (``SAI?``) and checks every configured axis is among them,
and reads the travel range once (``TMN?``/``TMX?``). Every command that changes state is sent
together with ``ERR?`` in one write (as PI's own library does with ``embederr``) and a nonzero
code raises :class:`~wavestack.drivers.pi_gcs.error_codes.GcsError`. A query that gets no answer
is explained by ``ERR?`` when the controller has an error to report (a GCS controller does not
answer a query it refuses).

A move (:meth:`PIHexapod.move_absolute`) reads the position back, then is refused whole, before
anything is sent, if any axis leaves the controller's travel range or the soft limits or steps
further than ``max_step`` from the position read back (:func:`~wavestack.drivers.pi_gcs.limits.move_refusals`);
it then passes the safety stage (:class:`~wavestack.drivers.safety.SafetyStage`, reset to the
position read back) and is refused unless the stage forwards it unchanged: a pose is never
clipped or shortened.

The pose convention (what X Y Z U V W mean) is in the package docstring.

References
----------
.. [1] Physik Instrumente, MS204E, "C-887 Hexapod Controller User Manual" (interfaces: TCP/IP port
   50000, RS-232 115200 baud).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from types import MappingProxyType

import numpy as np

from wavestack.drivers._checks import check_timeout, is_number
from wavestack.drivers.errors import DeviceTimeout, LimitError, ProtocolError
from wavestack.drivers.link import ByteLink, LinkedDevice, line_framing
from wavestack.drivers.pi_gcs import protocol as gcs
from wavestack.drivers.pi_gcs.error_codes import NO_ERROR, STOPPED_BY_COMMAND, GcsError
from wavestack.drivers.pi_gcs.limits import HexapodLimits, move_refusals, safety_limits
from wavestack.drivers.safety import SafetyStage, SafetyStatus

__all__ = ["DEFAULT_PORT", "HEXAPOD_AXES", "HexapodMove", "PIHexapod"]

logger = logging.getLogger(__name__)

HEXAPOD_AXES = ("X", "Y", "Z", "U", "V", "W")
#: PI's TCP port for GCS on its controllers (a ``tcp://HOST`` URL without a port).
DEFAULT_PORT = 50000
#: Largest |pivot coordinate| the driver sends, mm: beyond a hexapod's reach by far, and no NaN or
#: infinity (which the ``SPI`` text would carry as ``nan``/``inf``).
MAX_PIVOT_MM = 10_000.0
_ERR = b"ERR?\n"
_POLL_S = 0.02  # wait_on_target: pause between ONT? polls


@dataclass(frozen=True)
class HexapodMove:
    """What one :meth:`PIHexapod.move_absolute` sent.

    Attributes
    ----------
    target
        ``{axis: value}`` as sent (after quantisation to the wire's 9 decimals), mm or deg.
    start
        The position read back just before, ``{axis: value}`` for every configured axis.
    """

    target: Mapping[str, float]
    start: Mapping[str, float]


class PIHexapod(LinkedDevice):
    """A PI GCS 2.0 platform (hexapod or stage) on TCP or a serial URL.

    Parameters
    ----------
    url
        ``tcp://HOST[:PORT]`` (port 50000 by default) or anything ``serial.serial_for_url`` opens.
    axes
        The axes this driver moves, a subset of the controller's ``SAI?``.
    limits
        Soft limits and largest step per move for every axis of ``axes``.
    timeout_s
        Timeout of each exchange, s.

    Notes
    -----
    Thread-safe: one lock serialises every exchange (a command and its ``ERR?`` together); a
    :meth:`wait_on_target` releases it between polls, so :meth:`stop_all` from another thread gets
    through. :meth:`close` leaves the platform where it is.

    Examples
    --------
    >>> limits = HexapodLimits.uniform(("1", "2"), lower=-25.0, upper=25.0, max_step=5.0)
    >>> stage = PIHexapod("tcp://127.0.0.1:50000", axes=("1", "2"), limits=limits)
    >>> stage.name, stage.configured_axes
    ('PI GCS controller at tcp://127.0.0.1:50000', ('1', '2'))
    """

    def __init__(self, url: str, axes: Sequence[str] = HEXAPOD_AXES, *, limits: HexapodLimits,
                 timeout_s: float = 1.0) -> None:
        axes = tuple(gcs.check_axis_id(axis) for axis in axes)
        if not axes or len(set(axes)) != len(axes):
            raise ValueError(f"axes must be distinct GCS axis identifiers, got {axes!r}")
        missing = [axis for axis in axes if axis not in limits.soft]
        if missing:
            raise ValueError(f"limits: no soft limits and max_step for axes {missing} (limits cover {limits.axes})")
        check_timeout(timeout_s)
        self.url = url
        self.configured_axes = axes
        self.limits = limits
        self.timeout_s = float(timeout_s)
        self._model: str | None = None
        self._lock = threading.RLock()
        self._link = ByteLink(url, lambda: self.name, default_port=DEFAULT_PORT)
        self._controller_axes: tuple[str, ...] = ()
        self._travel: Mapping[str, tuple[float, float]] = MappingProxyType({})
        self._stage: SafetyStage | None = None
        self._stopped_since_move = False

    # ------------------------------------------------------------------------------ lifecycle
    @property
    def name(self) -> str:
        """Who this is in messages: ``"C-887 at tcp://10.0.0.5:50000"``."""
        return f"{self._model or 'PI GCS controller'} at {self.url}"

    @property
    def controller_limits(self) -> Mapping[str, tuple[float, float]]:
        """The travel range ``{axis: (TMN?, TMX?)}`` read at :meth:`open` (read-only mapping)."""
        return self._travel

    # ------------------------------------------------------------------------------ queries
    def identify(self) -> str:
        """The controller's ``*IDN?`` line (vendor, model, serial number, firmware)."""
        return " ".join(self._query(b"*IDN?\n", "*IDN?")).strip()

    def csv(self) -> str:
        """The GCS syntax version (``CSV?``), e.g. ``"2.0"``."""
        return " ".join(self._query(b"CSV?\n", "CSV?")).strip()

    def axes(self) -> tuple[str, ...]:
        """The controller's axes (``SAI?``), in its order."""
        return gcs.parse_axes(self._query(b"SAI?\n", "SAI?"), device=self.name)

    def position(self) -> dict[str, float]:
        """Current position of every configured axis (``POS?``), mm or deg."""
        return self._axis_query("POS?", gcs.parse_axis_values)

    def on_target(self) -> dict[str, bool]:
        """On-target state of every configured axis (``ONT?``)."""
        return self._axis_query("ONT?", gcs.parse_axis_flags)

    def servo(self) -> dict[str, bool]:
        """Servo state of every configured axis (``SVO?``)."""
        return self._axis_query("SVO?", gcs.parse_axis_flags)

    def referenced(self) -> dict[str, bool]:
        """Whether every configured axis is referenced (``FRF?``)."""
        return self._axis_query("FRF?", gcs.parse_axis_flags)

    def pivot(self) -> tuple[float, float, float]:
        """The pivot point (``SPI?``), mm, as (R, S, T) = (X, Y, Z)."""
        values = gcs.parse_axis_values(self._query(b"SPI?\n", "SPI?"), device=self.name, what="SPI?")
        try:
            return tuple(values[r] if r in values else values[x] for r, x in zip("RST", "XYZ"))  # type: ignore[return-value]
        except KeyError:
            raise ProtocolError(self.name, f"SPI?: expected R S T (or X Y Z) values, got {values}") from None

    def velocity(self) -> float:
        """The platform velocity (``VLS?``), mm/s."""
        return gcs.parse_number(self._query(b"VLS?\n", "VLS?"), device=self.name, what="VLS?")

    def ready(self) -> bool:
        """``#7``: True when the controller is ready, False while busy (e.g. referencing)."""
        with self._lock:
            deadline = time.monotonic() + self.timeout_s
            self._send(gcs.READY_STATUS, deadline, "#7")
            return gcs.parse_ready(self._link.receive(line_framing, deadline, during="#7"), device=self.name)

    def moving(self) -> dict[str, bool]:
        """``#5``: which of the controller's axes (``SAI?`` order) are moving."""
        with self._lock:
            deadline = time.monotonic() + self.timeout_s
            self._send(gcs.MOTION_STATUS, deadline, "#5")
            lines = self._reply(deadline, "#5")
            return gcs.parse_motion_mask(lines, self._controller_axes, device=self.name)

    # ----------------------------------------------------------------------------- commands
    def move_absolute(self, pose: Mapping[str, float]) -> HexapodMove:
        """Check, then move to ``pose`` (``MOV``); returns what was sent. Does not wait.

        Parameters
        ----------
        pose
            ``{axis: target}`` for some or all configured axes, mm (X Y Z) or deg (U V W);
            axes not given keep their target.

        Returns
        -------
        HexapodMove

        Raises
        ------
        ValueError
            An axis not configured (nothing sent).
        LimitError
            A non-finite value, a target outside the travel range or the soft limits, a step
            larger than ``max_step`` from the position read back, or a refusal of the safety
            stage; nothing was sent.
        GcsError
            The controller refused the move (``ERR?`` nonzero), e.g. 5 (servo off or not
            referenced).
        DeviceTimeout, DeviceDisconnected, ProtocolError
            As for every exchange.
        """
        unknown = [axis for axis in pose if axis not in self.configured_axes]
        if unknown or not pose:
            raise ValueError(f"{self.name}: pose must give some of the configured axes {self.configured_axes}, "
                             f"got {list(pose)}")
        bad = {axis: value for axis, value in pose.items() if not (is_number(value) and math.isfinite(value))}
        if bad:
            raise LimitError(self.name, f"refusing a move with non-finite or non-numeric targets {bad}; nothing sent")
        target = {axis: gcs.quantize(pose[axis]) for axis in self.configured_axes if axis in pose}
        with self._lock:
            start = self.position()
            refusals = move_refusals(target, start, self.limits, self._travel)
            if refusals:
                raise LimitError(self.name, "refusing the move, nothing sent: " + "; ".join(refusals))
            full = np.array([target.get(axis, start[axis]) for axis in self.configured_axes])
            stage = self._safety_stage(start)
            now = time.monotonic()
            proposal = stage.propose(full, measured_at_s=now, now_s=now)
            if proposal.status != SafetyStatus.OK or not np.array_equal(proposal.values, full):
                raise LimitError(self.name, f"refusing the move, nothing sent: the safety stage would change it "
                                 f"({proposal.reason})")
            self._command(gcs.encode_axis_values("MOV", target), "MOV")
            stage.commit(full)
            self._stopped_since_move = False
            logger.debug("%s: MOV %s from %s", self.name, target, start)
            return HexapodMove(target=MappingProxyType(target), start=MappingProxyType(start))

    def wait_on_target(self, timeout_s: float) -> dict[str, float]:
        """Poll ``ONT?`` until every configured axis is on target; return the position read back.

        On arrival ``ERR?`` is read too: after a stop (``#24``, ``HLT``) a PI controller sets the
        target to where the platform stopped, so ``ONT?`` alone would report a stopped move as
        arrived.

        Raises
        ------
        GcsError
            The controller reports an error (10 after a stop by anyone), or this driver stopped
            the platform since the last move.
        DeviceTimeout
            Not on target within ``timeout_s``; the message names the axes off target, their
            positions and whether they still move. The platform is not halted here.
        """
        check_timeout(timeout_s)
        deadline = time.monotonic() + timeout_s
        while True:
            state = self.on_target()
            if all(state.values()):
                return self._arrived()
            if time.monotonic() >= deadline:
                break
            time.sleep(_POLL_S)
        with self._lock:
            code = self.error_code()
            if code != NO_ERROR:
                raise GcsError(code, device=self.name, command="MOV (while waiting on target)")
            position, moving = self.position(), self.moving()
        off = {axis: position[axis] for axis, ok in state.items() if not ok}
        raise DeviceTimeout(self.name, f"not on target after {timeout_s:g} s: axes {off} (positions), "
                            f"moving {[a for a, m in moving.items() if m]}; expected ONT? = 1 on every axis")

    def _arrived(self) -> dict[str, float]:
        """On target: but a stopped platform is on target too (its target became where it stopped).

        A stop by this driver since the last move, or an error the controller still holds (10
        after a stop by another client or the front panel), makes the wait fail.
        """
        with self._lock:
            if self._stopped_since_move:
                raise GcsError(STOPPED_BY_COMMAND, device=self.name, command="HLT or #24 during the move")
            code = self.error_code()
            if code != NO_ERROR:
                raise GcsError(code, device=self.name, command="MOV (while waiting on target)")
            return self.position()

    def halt(self) -> None:
        """Stop the configured axes smoothly (``HLT``); the stop's error 10 is read and cleared."""
        with self._lock:
            self._stopped_since_move = True
            self._command(gcs.encode_command("HLT", *self.configured_axes), "HLT", allowed=(STOPPED_BY_COMMAND,))

    def stop_all(self) -> None:
        """Stop all motion at once (``#24``); then ``ERR?`` must read 10 (and clears it).

        Raises
        ------
        GcsError
            ``ERR?`` read another nonzero code (the stop itself was sent).
        """
        with self._lock:
            self._stopped_since_move = True
            deadline = time.monotonic() + self.timeout_s
            self._send(gcs.STOP_ALL, deadline, "#24")
            code = self.error_code()
        if code == NO_ERROR:
            logger.warning("%s: ERR? read 0 after #24; PI controllers set 10 (stopped by command)", self.name)
        elif code != STOPPED_BY_COMMAND:
            raise GcsError(code, device=self.name, command="#24")

    def set_servo(self, on: bool) -> None:
        """Switch the servo of every configured axis on or off (``SVO``)."""
        self._command(gcs.encode_axis_values("SVO", {axis: bool(on) for axis in self.configured_axes}), "SVO")

    def set_pivot(self, pivot: Sequence[float]) -> None:
        """Set the pivot point (``SPI R x S y T z``), mm; the controller refuses unless U = V = W = 0 (error 9)
        and within its range (error 17).

        Raises
        ------
        ValueError
            Not three finite numbers within +-``MAX_PIVOT_MM`` (nothing sent).
        """
        if len(pivot) != 3 or not all(is_number(v) and abs(v) <= MAX_PIVOT_MM for v in pivot):
            raise ValueError(f"{self.name}: pivot must be (x, y, z) in mm, each finite and within +-{MAX_PIVOT_MM:g} "
                             f"mm, got {pivot!r}; nothing sent")
        self._command(gcs.encode_axis_values("SPI", dict(zip("RST", (float(v) for v in pivot)))), "SPI")

    def set_velocity(self, velocity: float) -> None:
        """Set the platform velocity (``VLS``), mm/s, > 0."""
        if not (is_number(velocity) and math.isfinite(velocity) and velocity > 0):
            raise ValueError(f"{self.name}: velocity must be a finite number > 0 mm/s, got {velocity!r}")
        self._command(gcs.encode_command("VLS", float(velocity)), "VLS")

    def error_code(self) -> int:
        """Read (and so clear) the controller's last error code (``ERR?``)."""
        return gcs.parse_error_code(self._query(_ERR, "ERR?", explain=False), device=self.name)

    # ----------------------------------------------------------------------------- internals
    def _handshake(self, timeout_s: float) -> None:
        """After :meth:`open` connected: clear a stale error, read identity, GCS version, axes, travel range."""
        stale = self.error_code()
        if stale != NO_ERROR:
            logger.warning("%s: cleared a stale controller error %d at connect", self.name, stale)
        identity = self.identify()
        parts = [part.strip() for part in identity.split(",")]
        self._model = parts[1] if len(parts) >= 2 and parts[1] else None
        version = self.csv()
        if not version.startswith("2."):
            raise ProtocolError(self.name, f"CSV? answered {version!r}; this driver speaks GCS 2.0")
        self._controller_axes = self.axes()
        missing = [axis for axis in self.configured_axes if axis not in self._controller_axes]
        if missing:
            raise ProtocolError(self.name, f"configured axes {missing} are not among the controller's "
                                f"{list(self._controller_axes)} (SAI?)")
        low = self._axis_query("TMN?", gcs.parse_axis_values)
        high = self._axis_query("TMX?", gcs.parse_axis_values)
        self._travel = MappingProxyType({axis: (low[axis], high[axis]) for axis in self.configured_axes})
        safety_limits(self.limits, self._travel, self.configured_axes)  # raises on no overlap
        self._stage = None
        logger.info("%s open: %s, GCS %s, axes %s, travel %s", self.name, identity, version,
                    list(self._controller_axes), dict(self._travel))

    def _safety_stage(self, start: Mapping[str, float]) -> SafetyStage:
        """The stage, its last output reset to the position read back (refusal if outside the limits)."""
        if self._stage is None:
            try:
                self._stage = SafetyStage(safety_limits(self.limits, self._travel, self.configured_axes))
            except ValueError as error:
                raise LimitError(self.name, f"refusing every move: {error}") from None
        try:
            self._stage.reset([start[axis] for axis in self.configured_axes])
        except ValueError:
            raise LimitError(self.name, f"refusing the move, nothing sent: the platform sits at {dict(start)}, "
                             "outside the soft limits or travel range; move it back with the controller's own "
                             "tools or widen the soft limits") from None
        return self._stage

    def _axis_query(self, mnemonic: str, parse) -> dict:  # type: ignore[no-untyped-def]
        lines = self._query(gcs.encode_command(mnemonic, *self.configured_axes), mnemonic)
        values = parse(lines, device=self.name, what=mnemonic)
        missing = [axis for axis in self.configured_axes if axis not in values]
        if missing:
            raise ProtocolError(self.name, f"{mnemonic}: no value for axes {missing}, got {values}")
        return {axis: values[axis] for axis in self.configured_axes}

    def _query(self, data: bytes, during: str, *, explain: bool = True) -> list[str]:
        """Send a query and read its reply; a missing reply is explained by ERR? when it can be."""
        with self._lock:
            deadline = time.monotonic() + self.timeout_s
            self._send(data, deadline, during)
            try:
                return self._reply(deadline, during)
            except DeviceTimeout as timeout:
                if not explain:
                    raise
                try:
                    code = self.error_code()
                except DeviceTimeout:
                    raise timeout from None
                if code != NO_ERROR:
                    raise GcsError(code, device=self.name, command=during) from timeout
                raise

    def _command(self, data: bytes, during: str, *, allowed: tuple[int, ...] = ()) -> None:
        """Send a command that changes state together with ERR?; a nonzero code not in ``allowed`` raises."""
        with self._lock:
            deadline = time.monotonic() + self.timeout_s
            self._send(data + _ERR, deadline, during)
            code = gcs.parse_error_code(self._reply(deadline, f"ERR? after {during}"), device=self.name)
        if code != NO_ERROR and code not in allowed:
            raise GcsError(code, device=self.name, command=data.decode("ascii").strip())

    def _send(self, data: bytes, deadline: float, during: str) -> None:
        """Write one or more commands; late bytes of a failed exchange are drained first."""
        if self._link.dirty:
            self._link.require_open()
            self._link.drain(deadline)
        self._link.send(data, deadline, during=during)

    def _reply(self, deadline: float, during: str) -> list[str]:
        """One complete reply (its lines) before ``deadline``."""
        return self._link.receive(partial(gcs.split_reply, device=self.name), deadline, during=during)
