"""Hostile peers of the piezo's serial-over-TCP bridge and of the hexapod simulator, on loopback.

A silent client may not keep the bridge from the station for longer than its inactivity timeout;
a GCS client that never reads may not stall the hexapod for anyone else; a pivot has a bound on
both ends of the wire. Every loop is bounded.
"""

from __future__ import annotations

import socket
import time

import pytest

from wavestack.drivers.errors import DeviceError
from wavestack.drivers.mdt693b import MDT693B
from wavestack.drivers.pi_gcs import GcsError, HexapodLimits, PIHexapod
from wavestack.simulators.align_bench_remote import SerialTcpBridge
from wavestack.simulators.mdt693b import MDT693BDevice
from wavestack.simulators.pi_gcs import HexapodSimSettings, HexapodSimulator

AXES = ("X", "Y", "Z", "U", "V", "W")
LIMITS = HexapodLimits.uniform(AXES, lower=-5.0, upper=5.0, max_step=1.0)


def test_a_silent_client_keeps_the_piezo_bridge_no_longer_than_its_idle_timeout() -> None:
    with SerialTcpBridge(MDT693BDevice(), idle_timeout_s=0.5) as bridge:
        silent = socket.create_connection(("127.0.0.1", bridge.port), timeout=5.0)  # connects, says nothing
        try:
            time.sleep(0.2)  # it holds the one client slot now
            piezo = MDT693B(f"socket://127.0.0.1:{bridge.port}", timeout_s=0.5)
            deadline = time.monotonic() + 8.0
            while True:  # the station's driver retries as its reconnect does, within a bound
                try:
                    piezo.open()
                    break
                except DeviceError:
                    piezo.close()
                    assert time.monotonic() < deadline, "the silent client kept the bridge"
            assert piezo.identity.model.startswith("MDT69")
            piezo.close()
            assert silent.recv(16) == b""  # the silent client was disconnected
        finally:
            silent.close()


def test_a_gcs_client_that_never_reads_stalls_no_one() -> None:
    with HexapodSimulator(HexapodSimSettings()) as sim:
        hog = socket.socket()
        hog.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # small buffers: they fill at once
        hog.settimeout(5.0)
        hog.connect(("127.0.0.1", sim.port))
        try:
            hog.setblocking(False)
            queries = b"POS?\n" * 200_000  # ~18 MB of answers it will never read
            try:
                sent = hog.send(queries)  # as much as the buffers take at once
            except OSError:
                sent = 0
            assert sent > 0
            with PIHexapod(f"tcp://127.0.0.1:{sim.port}", limits=LIMITS, timeout_s=1.0) as hexapod:
                slowest = 0.0
                for _ in range(20):
                    start = time.monotonic()
                    hexapod.position()
                    slowest = max(slowest, time.monotonic() - start)
            # a stalled loop shows as a query waiting seconds (the old send timeout was 2 s per reply);
            # 0.5 s is far above a loopback exchange on a loaded machine
            assert slowest < 0.5
            deadline = time.monotonic() + 5.0
            while sim.client_count > 0 and time.monotonic() < deadline:
                time.sleep(0.02)
            assert sim.client_count == 0  # the hog was disconnected once its unread replies passed the bound
        finally:
            hog.close()


def test_a_pivot_out_of_range_is_refused_by_the_driver_and_by_the_controller() -> None:
    with HexapodSimulator(HexapodSimSettings(pivot_limit_mm=100.0)) as sim:
        with PIHexapod(f"tcp://127.0.0.1:{sim.port}", limits=LIMITS, timeout_s=1.0) as hexapod:
            for bad in ((float("nan"), 0.0, 0.0), (0.0, float("inf"), 0.0), (0.0, 0.0, 1e6)):
                with pytest.raises(ValueError, match="nothing sent"):
                    hexapod.set_pivot(bad)
            with pytest.raises(GcsError) as refused:
                hexapod.set_pivot((0.0, 0.0, 500.0))  # within the driver's bound, beyond this controller's
            assert refused.value.code == 17
            hexapod.set_pivot((0.0, 0.0, 50.0))
            assert hexapod.pivot() == (0.0, 0.0, 50.0)
    assert not any("nan" in line.lower() or "inf" in line.lower() for line in sim.controller.commands)


def test_silent_gcs_clients_make_room_and_busy_ones_keep_their_places() -> None:
    with HexapodSimulator(HexapodSimSettings(), max_clients=2, quiet_s=1.0) as sim:
        silent = [socket.create_connection(("127.0.0.1", sim.port), timeout=5.0) for _ in range(2)]
        try:
            time.sleep(1.2)  # both quiet now: the station's controller link takes the place of the quieter
            with PIHexapod(f"tcp://127.0.0.1:{sim.port}", limits=LIMITS, timeout_s=1.0) as hexapod:
                hexapod.position()
                assert silent[0].recv(16) == b""  # closed to make room
                with socket.create_connection(("127.0.0.1", sim.port), timeout=5.0) as third:
                    assert silent[1].recv(16) == b""  # the other quiet one made room for it
                    hexapod.position()  # busy: the station keeps its place
                    with socket.create_connection(("127.0.0.1", sim.port), timeout=5.0) as fourth:
                        assert fourth.recv(16) == b"" and sim.refused == 1  # nobody quiet: refused
                    third.sendall(b"CSV?\n")
                    assert third.recv(16) == b"2.0\n"
                hexapod.position()
        finally:
            for sock in silent:
                sock.close()
