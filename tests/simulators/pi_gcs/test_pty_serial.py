"""The same controller on a pseudo-terminal, opened with pyserial like an RS-232 port."""

from __future__ import annotations

import time

import serial

from wavestack.simulators.pi_gcs import GcsController, GcsPtyBridge, HexapodSimSettings


def _reply(port: serial.Serial) -> bytes:
    answer = b""
    while not answer.endswith(b"\n") or answer.endswith(b" \n"):
        chunk = port.read(1)
        assert chunk, f"timed out after {answer!r}"
        answer += chunk
    return answer


def test_a_serial_port_speaks_gcs_through_the_pty() -> None:
    controller = GcsController(HexapodSimSettings())
    with GcsPtyBridge(controller) as bridge:
        port = serial.serial_for_url(bridge.port_path, baudrate=115200, timeout=5.0)
        try:
            port.write(b"MOV X 1\nERR?\nPOS? X Y\n")
            assert _reply(port) == b"0\n"
            assert _reply(port).startswith(b"X=") and controller.targets["X"] == 1.0
            port.write(b"\x07")
            assert _reply(port) == b"\xb1\n"
            controller.faults.split_replies(pieces=2, gap_s=0.01)
            port.write(b"SAI?\n")
            assert _reply(port) == b"X \nY \nZ \nU \nV \nW\n"
        finally:
            port.close()


def test_a_dropped_connection_unplugs_the_pty() -> None:
    controller = GcsController(HexapodSimSettings())
    with GcsPtyBridge(controller) as bridge:
        controller.faults.drop_connection()
        port = serial.serial_for_url(bridge.port_path, timeout=5.0)
        try:
            port.write(b"MOV X 1\n")
            deadline = time.monotonic() + 5.0
            while not bridge.unplugged and time.monotonic() < deadline:  # poll with a deadline
                time.sleep(0.02)
            assert bridge.unplugged
            assert controller.targets["X"] == 0.0
        finally:
            port.close()
