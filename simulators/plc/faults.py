"""Fault switches of the simulated PLC, flipped by tests or an operator while it serves.

Reply faults act on the encoded Modbus/TCP reply (MBAP header + PDU) just before it is written to
the socket, through pymodbus's ``trace_packet`` hook, so the request is still executed: a dropped
reply to a command means the command took effect but the host never heard so. One-shot faults
(``drop_replies``, ``truncate_replies``, ``corrupt_replies``) hit the next ``n`` replies, optionally
only replies to one function code; ``delay_s``, ``freeze_heartbeat_echo`` and ``estop`` stay until
cleared. All methods are thread-safe.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass

__all__ = ["SimFaults"]

_log = logging.getLogger(__name__)

_MBAP_LENGTH = 7  # transaction id, protocol id, length, unit id
_UNDEFINED_FUNCTION_CODE = 0x7F  # no standard PDU: a client cannot decode the reply


@dataclass
class _OneShot:
    kind: str
    remaining: int
    function_code: int | None
    keep_bytes: int = 0


class SimFaults:
    """Switches that make the simulated PLC misbehave.

    Attributes
    ----------
    delay_s
        Every request is answered this much later, s (0 = at once).
    freeze_heartbeat_echo
        The PLC logic stops copying the heartbeat into the status block's echo register.
    estop
        The emergency stop is pressed: status shows e-stop and fault, commands answer exception 4.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._one_shots: list[_OneShot] = []
        self.delay_s = 0.0
        self.freeze_heartbeat_echo = False
        self.estop = False

    def drop_replies(self, n: int = 1, *, function_code: int | None = None) -> None:
        """Execute the next ``n`` requests (of ``function_code``, if given) but send no reply."""
        self._add(_OneShot("drop", n, function_code))

    def truncate_replies(self, n: int = 1, *, keep_bytes: int = 9, function_code: int | None = None) -> None:
        """Send only the first ``keep_bytes`` bytes of the next ``n`` replies (the header promises more)."""
        if keep_bytes < 0:
            raise ValueError(f"keep_bytes must be >= 0, got {keep_bytes}")
        self._add(_OneShot("truncate", n, function_code, keep_bytes))

    def corrupt_replies(self, n: int = 1, *, function_code: int | None = None) -> None:
        """Replace the function code of the next ``n`` replies by an undefined one (0x7F)."""
        self._add(_OneShot("corrupt", n, function_code))

    def clear(self) -> None:
        """Switch every fault off."""
        with self._lock:
            self._one_shots.clear()
        self.delay_s = 0.0
        self.freeze_heartbeat_echo = False
        self.estop = False

    @property
    def pending_reply_faults(self) -> int:
        """One-shot reply faults not yet used."""
        with self._lock:
            return sum(shot.remaining for shot in self._one_shots)

    def apply_to_reply(self, frame: bytes) -> bytes:
        """The bytes actually sent for an encoded reply ``frame`` (unchanged without a pending fault)."""
        function_code = frame[_MBAP_LENGTH] & 0x7F if len(frame) > _MBAP_LENGTH else None
        with self._lock:
            shot = next((s for s in self._one_shots
                         if s.function_code is None or s.function_code == function_code), None)
            if shot is None:
                return frame
            shot.remaining -= 1
            if shot.remaining <= 0:
                self._one_shots.remove(shot)
        _log.warning("PLC simulator fault: %s reply to FC%s", shot.kind, function_code)
        if shot.kind == "drop":
            return b""
        if shot.kind == "truncate":
            return frame[:shot.keep_bytes]
        return frame[:_MBAP_LENGTH] + bytes([_UNDEFINED_FUNCTION_CODE]) + frame[_MBAP_LENGTH + 1:]

    def _add(self, shot: _OneShot) -> None:
        if shot.remaining < 1:
            raise ValueError(f"n must be >= 1, got {shot.remaining}")
        with self._lock:
            self._one_shots.append(shot)
