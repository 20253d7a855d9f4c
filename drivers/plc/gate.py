"""When the PLC may get a command: the readiness gate the link applies before every command (pure).

A PLC that is not scanning (its logic no longer echoes the heartbeat), whose watchdog has tripped,
whose emergency stop is pressed, that is not ready or busy gets no command; the link says why with
:class:`PlcNotReady` and sends nothing. A latched fault bit alone (the last command was refused)
does not block: the next valid command clears it. The start-up self-check of the float32 byte
order (:func:`decode_self_check`) is the first gate: a link whose check failed sends nothing.
"""

from __future__ import annotations

from collections.abc import Sequence

from wavestack.drivers.errors import DeviceError, ProtocolError
from wavestack.drivers.plc.codec import WORD_ORDERS, decode_float32, round_to_float32
from wavestack.drivers.plc.register_map import RegisterBlock
from wavestack.drivers.plc.status import PlcStatus

__all__ = ["HeartbeatEchoStale", "PlcNotReady", "command_refusal", "decode_self_check", "echo_lag_error", "no_scan_since",
           "not_ready"]


class HeartbeatEchoStale(ProtocolError):
    """The PLC answers but its logic no longer echoes the heartbeat (stopped or frozen program)."""


class PlcNotReady(DeviceError):
    """The PLC cannot take a command now (not scanning, tripped, e-stop, not ready or busy); nothing was sent."""


def command_refusal(device: str, *, monitor: bool, self_check_passed: bool, echo_stale: bool) -> DeviceError | None:
    """The error for a command the link may not send at all (nothing goes on the wire), or None.

    A monitor link sends none; a link whose self-check has not passed sends none (fails closed); a
    link whose last heartbeat showed a stale echo sends none until a heartbeat is echoed again.
    """
    if monitor:
        return ProtocolError(device, "refusing to send a command: a monitor link sends none")
    if not self_check_passed:
        return ProtocolError(device, "refusing to send a command: the start-up self-check has not passed "
                             "(call self_check first)")
    if echo_stale:
        return PlcNotReady(device, "refusing to send a command: the last heartbeat showed a stale echo (the PLC "
                           "program is not scanning)")
    return None


def no_scan_since(echo_at_last_command: int | None, beat: int, status: PlcStatus) -> str | None:
    """Why no PLC scan is seen since the last command, or None (pure).

    The echo may trail the heartbeat by a few beats (a slow scan), so a program that has just
    stopped is not told from a slow one for that many beats; a command therefore also needs the
    echo to have moved since the gate passed the previous command (or to equal the last beat).

    Examples
    --------
    >>> from wavestack.drivers.plc.status import decode_status
    >>> status = decode_status([1, 7, 41])   # ready, last accepted id 7, echo 41
    >>> no_scan_since(41, 42, status) is not None, no_scan_since(40, 42, status), no_scan_since(41, 41, status)
    (True, None, None)
    """
    echo = status.heartbeat_echo
    if echo_at_last_command is None or echo != echo_at_last_command or echo == beat:
        return None
    return (f"not seen scanning since the last command: the heartbeat echo has stayed at {echo} while the host "
            f"sent {beat}; expected the echo to advance (a PLC scan) between commands")


def not_ready(status: PlcStatus) -> str | None:
    """Why a PLC in ``status`` may not get a command, or None when it may."""
    if status.watchdog_tripped:
        return "tripped (watchdog): an operator re-arms it with `wavestack plc rearm`"
    if status.estop:
        return "in emergency stop"
    if status.busy:
        return "busy with a command"
    if not status.ready:
        return f"not ready (status word {status.raw_word})"
    return None


def echo_lag_error(device: str, beat: int, status: PlcStatus, max_lag: int, register: int) -> HeartbeatEchoStale | None:
    """The error for a heartbeat echo trailing the host's heartbeat ``beat`` by more than ``max_lag``, or None.

    Parameters
    ----------
    device
        How errors name the PLC.
    beat
        The host's last heartbeat value (0..65535; the lag is counted modulo 2**16).
    status
        The status read (a tripped watchdog reports no echo: no error here, the trip is reported).
    max_lag
        Beats the echo may trail.
    register
        The echo's register, for the message.
    """
    lag = (beat - (status.heartbeat_echo or 0)) & 0xFFFF
    if status.watchdog_tripped or lag <= max_lag:
        return None
    return HeartbeatEchoStale(device, f"heartbeat echo (register {register}) is {status.heartbeat_echo} while the "
                              f"host sent {beat}: {lag} beats behind, expected at most {max_lag}; the PLC program "
                              "is not scanning")


def decode_self_check(device: str, block: RegisterBlock, registers: Sequence[int], constant: float) -> float:
    """The self-check constant decoded from ``registers`` with the block's word order.

    Raises
    ------
    ProtocolError
        It decodes to something other than float32(``constant``); the message names the configured
        word order and the order that would decode it.
    """
    assert block.word_order is not None
    value = decode_float32(registers, block.word_order)
    expected = round_to_float32(constant)
    if value != expected:
        matching = [o for o in WORD_ORDERS if decode_float32(registers, o) == expected]
        hint = (f"it decodes correctly with word order {matching[0]}" if matching else
                "no byte order decodes it: check the register address and the constant")
        raise ProtocolError(device, f"start-up self-check failed: registers {block.start}-{block.stop - 1} = "
                            f"{list(registers)} decode to {value!r} with the configured word order "
                            f"{block.word_order}, expected {expected!r}; {hint}. Commands are refused until the "
                            "self-check passes.")
    return value
