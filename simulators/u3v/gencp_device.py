"""Device side of GenCP over the USB3 Vision control endpoints (commands on 0x01, acks on 0x81).

Pure and single-threaded: :class:`GenCPDevice` takes the bytes of one bulk OUT transfer and the
device time, executes the command against a :class:`~.registers.RegisterMap` and queues the
acknowledge(s) with the time each becomes readable. The camera holds the lock and does the waiting.

Command: prefix u32 0x43563355, flags u16 (0x4000 request acknowledge), command_id u16,
scd_length u16, request_id u16, SCD. Acknowledge: prefix, status u16, command_id u16, scd_length
u16, request_id u16, SCD. How malformed input is answered (documented choices, the sheet leaves
them open):

- fewer than 4 bytes or a wrong prefix: no acknowledge (the device cannot tell it is GenCP);
- right prefix but fewer than 12 bytes, or ``scd_length`` different from the bytes that follow:
  INVALID_HEADER, echoing whatever command/request id bytes arrived (zero-padded);
- a command longer than the SBRM maximum command transfer length: INVALID_PARAMETER;
- an unknown command id: NOT_IMPLEMENTED;
- READMEM with an SCD other than 12 bytes, a zero length, or a length whose acknowledge would
  exceed the maximum acknowledge transfer length: INVALID_PARAMETER;
- WRITEMEM with no data: INVALID_PARAMETER.

The acknowledge's command id is the command id + 1 (READMEM_ACK, WRITEMEM_ACK, or cmd+1 for an
unknown command). Error acknowledges carry an empty SCD, except WRITEMEM_ACK which always carries
(reserved u16, bytes_written u16). Without the request-acknowledge flag a valid command is executed
silently; header errors are still answered (the flags themselves may be the corruption).
"""

from __future__ import annotations

import logging
import struct
from collections import deque
from dataclasses import dataclass

from wavestack.simulators.u3v.registers import GenCPStatus, RegisterMap

_log = logging.getLogger(__name__)

CONTROL_PREFIX = 0x43563355
FLAG_REQUEST_ACK = 0x4000
READMEM_CMD = 0x0800
READMEM_ACK = 0x0801
WRITEMEM_CMD = 0x0802
WRITEMEM_ACK = 0x0803
PENDING_ACK = 0x0805
HEADER = struct.Struct("<IHHHH")
_READMEM_SCD = struct.Struct("<QHH")
_ACK_DEPTH = 16  # acknowledges the device buffers before it drops the oldest


@dataclass(frozen=True)
class Acknowledge:
    """One acknowledge packet as the device sends it."""

    status: int
    command_id: int
    request_id: int
    scd: bytes = b""

    def to_bytes(self) -> bytes:
        """Wire form: 12-byte header then the SCD."""
        return HEADER.pack(CONTROL_PREFIX, self.status, self.command_id, len(self.scd), self.request_id) + self.scd


class GenCPDevice:
    """Parses commands, executes them on a register map and queues acknowledges.

    Parameters
    ----------
    registers
        The device's register space.
    max_command_bytes, max_ack_bytes
        SBRM maximum command / acknowledge transfer lengths (whole packets, bytes).
    """

    def __init__(self, registers: RegisterMap, *, max_command_bytes: int, max_ack_bytes: int) -> None:
        self._registers = registers
        self._max_command = max_command_bytes
        self._max_ack = max_ack_bytes
        self._queue: deque[tuple[int, bytes]] = deque()
        self.commands_received = 0

    def receive(self, packet: bytes, now_ns: int, pending_ack_ms: int = 0) -> None:
        """Handle one command transfer written to EP 0x01.

        Parameters
        ----------
        packet
            The bytes the host wrote.
        now_ns
            Device time, ns.
        pending_ack_ms
            If > 0, answer first with PENDING_ACK advertising this many ms, and make the real
            acknowledge readable only ``pending_ack_ms / 2`` ms later.
        """
        self.commands_received += 1
        ack = self.execute(packet)
        if ack is None:
            return
        ready = now_ns
        if pending_ack_ms > 0:
            timeout_ms = min(int(pending_ack_ms), 0xFFFF)
            self._push(now_ns, Acknowledge(0, PENDING_ACK, ack.request_id, struct.pack("<HH", 0, timeout_ms)))
            ready = now_ns + timeout_ms * 500_000  # half the advertised time, in ns
        self._push(ready, ack)

    def execute(self, packet: bytes) -> Acknowledge | None:
        """Execute one command; the acknowledge to send, or None when none is due."""
        if len(packet) < 4 or struct.unpack_from("<I", packet)[0] != CONTROL_PREFIX:
            _log.debug("control transfer of %d bytes without the U3VC prefix ignored", len(packet))
            return None
        header = packet[:HEADER.size].ljust(HEADER.size, b"\0")
        _, flags, command_id, scd_length, request_id = HEADER.unpack(header)
        ack_id = (command_id + 1) & 0xFFFF
        if len(packet) < HEADER.size or scd_length != len(packet) - HEADER.size:
            return Acknowledge(GenCPStatus.INVALID_HEADER, ack_id, request_id)
        scd = packet[HEADER.size:]
        if command_id == READMEM_CMD:
            status, reply = self._readmem(scd, len(packet))
        elif command_id == WRITEMEM_CMD:
            status, reply = self._writemem(scd, len(packet))
        else:
            status, reply = GenCPStatus.NOT_IMPLEMENTED, b""
        if not flags & FLAG_REQUEST_ACK:
            return None
        return Acknowledge(status, ack_id, request_id, reply)

    def _readmem(self, scd: bytes, packet_length: int) -> tuple[GenCPStatus, bytes]:
        if packet_length > self._max_command or len(scd) != _READMEM_SCD.size:
            return GenCPStatus.INVALID_PARAMETER, b""
        address, _, length = _READMEM_SCD.unpack(scd)
        if length == 0 or HEADER.size + length > self._max_ack:
            return GenCPStatus.INVALID_PARAMETER, b""
        status, data = self._registers.read(address, length)
        return status, data if status == GenCPStatus.SUCCESS else b""

    def _writemem(self, scd: bytes, packet_length: int) -> tuple[GenCPStatus, bytes]:
        if packet_length > self._max_command or len(scd) <= 8:
            return GenCPStatus.INVALID_PARAMETER, struct.pack("<HH", 0, 0)
        address = struct.unpack_from("<Q", scd)[0]
        status, written = self._registers.write(address, scd[8:])
        return status, struct.pack("<HH", 0, written)

    def _push(self, ready_ns: int, ack: Acknowledge) -> None:
        if self._queue:  # acknowledges leave in order
            ready_ns = max(ready_ns, self._queue[-1][0])
        if len(self._queue) >= _ACK_DEPTH:
            _log.warning("acknowledge queue full: oldest unread acknowledge dropped")
            self._queue.popleft()
        self._queue.append((ready_ns, ack.to_bytes()))

    def next_ready_ns(self) -> int | None:
        """Device time at which the next acknowledge becomes readable, or None if none is queued."""
        return self._queue[0][0] if self._queue else None

    def take(self, now_ns: int) -> bytes | None:
        """Pop the next acknowledge if it is readable at ``now_ns``."""
        if self._queue and self._queue[0][0] <= now_ns:
            return self._queue.popleft()[1]
        return None

    def clear(self) -> None:
        """Forget queued acknowledges (reset, unplug)."""
        self._queue.clear()
