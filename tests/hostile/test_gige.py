"""A second host on the simulated GigE Vision camera's control port, on loopback only.

GVCP has no authentication: the camera's control privilege (CCP) is the role. A host that does not
hold it may read registers (a monitor) but neither write nor ask for packet resends, which would
spend the station's link on a flood of old blocks. Every loop here is bounded by a count.
"""

from __future__ import annotations

import socket
import struct

import numpy as np

from wavestack.drivers.gige import GigECamera
from wavestack.simulators.gige import GigESimSettings, SimulatedGigECamera

TIMEOUT_S = 2.0
WIDTH, HEIGHT = 96, 64
COMMAND = struct.Struct(">BBHHH")  # key 0x42, flags (0x01: acknowledge), command, length, request id
ACK = struct.Struct(">HHHH")  # status, answer, length, request id
PACKETRESEND, READREG, WRITEREG = 0x0040, 0x0080, 0x0082
SUCCESS, ACCESS_DENIED = 0x0000, 0x8006
CCP, HEARTBEAT_TIMEOUT = 0x0A00, 0x0938


def ramp(block_id: int, device_time_ns: int, exposure_us: float) -> tuple[np.ndarray, int]:
    rows, cols = np.indices((HEIGHT, WIDTH))
    return ((rows * WIDTH + cols + 7 * block_id) % 4096).astype(np.uint16), block_id


def _ask(sock: socket.socket, address: tuple[str, int], code: int, payload: bytes, request_id: int) -> int:
    """Send one acknowledged command from ``sock``; its acknowledge's status."""
    sock.sendto(COMMAND.pack(0x42, 0x01, code, len(payload), request_id) + payload, address)
    status, _, _, answered = ACK.unpack_from(sock.recvfrom(2048)[0])
    assert answered == request_id
    return status


def test_a_second_host_may_read_but_not_write_or_flood_resends() -> None:
    settings = GigESimSettings(width=WIDTH, height=HEIGHT, frame_rate_hz=100.0)
    with SimulatedGigECamera(settings, ramp) as sim, \
            GigECamera.open(sim.url, timeout_s=TIMEOUT_S, packet_size=1500) as camera:
        camera.start()
        first = camera.read_frame(TIMEOUT_S).frame_id
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as intruder:
            intruder.settimeout(TIMEOUT_S)
            address = (sim.host, sim.port)
            assert _ask(intruder, address, READREG, struct.pack(">I", HEARTBEAT_TIMEOUT), 1) == SUCCESS
            for request_id, (register, value) in enumerate([(CCP, 2), (HEARTBEAT_TIMEOUT, 600_000)], start=2):
                assert _ask(intruder, address, WRITEREG, struct.pack(">II", register, value), request_id) \
                    == ACCESS_DENIED
            # every packet of every kept block, 200 times over: none may leave the camera for it
            asks = [struct.pack(">HHII", 0, block, 0, 0xFFFFFF) for block in range(1, 9)] * 25
            statuses = {_ask(intruder, address, PACKETRESEND, body, 10 + i) for i, body in enumerate(asks)}
        assert statuses == {ACCESS_DENIED}
        frames = [camera.read_frame(TIMEOUT_S) for _ in range(5)]
        camera.stop()
        assert sim.counters["resent"] == 0 and sim.counters["resends_refused"] == len(asks)
        assert all(np.array_equal(f.pixels, ramp(f.frame_id, 0, 0.0)[0]) for f in frames)
        assert first < frames[0].frame_id < frames[-1].frame_id
