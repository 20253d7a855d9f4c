"""Hostile peers of the USB-over-TCP bridge and the ``usbtcp://`` camera driver, on loopback only.

The server (:class:`~wavestack.simulators.usb_tcp.UsbTcpServer`) against a second client, oversize
and malformed requests, a half-sent request and a flood of connections; the driver
(:class:`~wavestack.drivers.usb_tcp.UsbTcpBackend`) against a server that never answers and one
that answers nonsense. Every loop here is bounded (a deadline or a count).
"""

from __future__ import annotations

import json
import socket
import struct
import textwrap
import threading
import time
import tracemalloc
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from wavestack.cli import EXIT_DEVICE_ERROR, main
from wavestack.drivers import DeviceError
from wavestack.drivers.u3v import U3VCamera, U3VCounters
from wavestack.drivers.usb_tcp import UsbTcpBackend
from wavestack.simulators.u3v import SimulatedU3VCamera, SimulatedUsbBackend, U3VSimSettings
from wavestack.simulators.usb_tcp import UsbTcpServer

HEAD = struct.Struct(">II")
WIDTH, HEIGHT = 24, 10
TIMEOUT_S = 5.0  # bounds a hang only


def ramp(block_id: int, device_time_ns: int, exposure_us: float) -> tuple[np.ndarray, None]:
    return (np.arange(HEIGHT * WIDTH, dtype=np.uint16).reshape(HEIGHT, WIDTH) + block_id) % 4096, None


def _sim_camera() -> SimulatedU3VCamera:
    return SimulatedU3VCamera(U3VSimSettings(serial="SIM-TCP", width=WIDTH, height=HEIGHT, frame_rate_hz=200.0,
                                             pixel_format="Mono12"), ramp)


def _camera_bus(sim: SimulatedU3VCamera | None = None) -> SimulatedUsbBackend:
    return SimulatedUsbBackend([sim if sim is not None else _sim_camera()])


class RawClient:
    """A peer that speaks the wire format by hand."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=TIMEOUT_S)

    def send(self, header: object, payload: bytes = b"", *, raw: bytes | None = None) -> None:
        body = raw if raw is not None else json.dumps(header).encode()
        self.sock.sendall(HEAD.pack(len(body), len(payload)) + body + payload)

    def reply(self) -> tuple[dict, bytes]:
        size, data_size = HEAD.unpack(self._exactly(HEAD.size))
        return json.loads(self._exactly(size)), self._exactly(data_size)

    def call(self, op: str, payload: bytes = b"", **args: object) -> tuple[dict, bytes]:
        self.send({"op": op, "args": args}, payload)
        return self.reply()

    def closed_within(self, seconds: float) -> bool:
        self.sock.settimeout(seconds)
        try:
            return self.sock.recv(1 << 16) == b"" or self.sock.recv(1 << 16) == b""
        except TimeoutError:
            return False
        except ConnectionResetError:
            return True

    def _exactly(self, count: int) -> bytes:
        data = b""
        while len(data) < count:
            chunk = self.sock.recv(count - len(data))
            if not chunk:
                raise ConnectionError("closed")
            data += chunk
        return data

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> RawClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def test_a_second_client_cannot_steal_frames_or_close_the_station_handles() -> None:
    sim = _sim_camera()
    with UsbTcpServer(_camera_bus(sim)) as server:
        backend = UsbTcpBackend("127.0.0.1", server.port)
        with U3VCamera.open(backend=backend, serial="SIM-TCP", timeout_s=TIMEOUT_S) as camera:
            camera.start()
            first = camera.read_frame(timeout_s=TIMEOUT_S).frame_id
            with RawClient(server.port) as intruder:
                assert "value" in intruder.call("hello", session=None)[0]
                answers = [intruder.call(op, handle=ref, ep=0x81, intf=1, size=1 << 16, timeout=100)[0]
                           for ref in range(1, 40) for op in ("bulk_read", "close_device")]
                # the station's handles are not the intruder's: every one is closed for it, nothing was read
                assert all(a.get("usb_error", [None, None, None])[2] == 19 or a == {"value": None} for a in answers)
                assert not any(isinstance(a.get("value"), int) and a["value"] > 0 for a in answers)
                ids = [camera.read_frame(timeout_s=TIMEOUT_S).frame_id for _ in range(5)]
                assert first < ids[0] < ids[-1]
                # every block the camera began reached the station whole (one may be in flight), none was cut
                before, sent, after = camera.counters(), sim.counters.blocks_sent, camera.counters()
                assert _blocks_seen(before) <= sent <= _blocks_seen(after) + 1
                assert after.discarded_blocks == after.transfer_errors == 0
            camera.stop()
        backend.close()


def _blocks_seen(counters: U3VCounters) -> int:
    """Blocks that reached the driver: frames acquired less the ones only inferred from a gap in ids."""
    return counters.acquired - counters.dropped_in_gaps + counters.discarded_blocks


def test_a_second_session_may_look_but_not_claim_an_owned_camera() -> None:
    with UsbTcpServer(_camera_bus()) as server:
        owner = UsbTcpBackend("127.0.0.1", server.port)
        with U3VCamera.open(backend=owner, serial="SIM-TCP", timeout_s=TIMEOUT_S):
            other = UsbTcpBackend("127.0.0.1", server.port)
            with pytest.raises(DeviceError):
                U3VCamera.open(backend=other, timeout_s=1.0)
            other.close()
        owner.close()


def test_oversize_requests_are_answered_and_allocate_nothing() -> None:
    with UsbTcpServer(_camera_bus()) as server:
        peer = RawClient(server.port)
        peer.call("hello", session=None)
        devices, _ = peer.call("enumerate_devices")
        handle = peer.call("open_device", dev=devices["value"][0][0])[0]["value"]
        tracemalloc.start()
        try:
            big_read, _ = peer.call("bulk_read", handle=handle, ep=0x81, intf=1, size=1 << 29, timeout=10)
            _, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
        assert big_read["usb_error"][2] == 22 and peak < 16 << 20  # EINVAL; no 512 MiB buffer was made
        assert "value" in peer.call("get_configuration", handle=handle)[0]  # the connection goes on
        peer.sock.sendall(HEAD.pack(1 << 30, 0))  # a header that declares 1 GiB
        answer, _ = peer.reply()
        assert answer["usb_error"][2] == 75 and peer.closed_within(TIMEOUT_S)  # EOVERFLOW, then closed
        peer.close()


def test_every_bad_request_is_answered_and_the_connection_goes_on() -> None:
    with UsbTcpServer(_camera_bus()) as server:
        peer = RawClient(server.port)
        assert peer.call("enumerate_devices")[0]["usb_error"][2] == 13  # EACCES: no hello yet
        peer.call("hello", session=None)
        peer.send(None, raw=b"{not json")
        assert "usb_error" in peer.reply()[0]
        peer.send([1, 2, 3])
        assert "usb_error" in peer.reply()[0]
        for op, args in (("no_such_op", {}), ("get_configuration_descriptor", {"dev": "x", "config": 0}),
                         ("open_device", {"dev": 10 ** 30}), ("bulk_write", {"handle": None}),
                         ("ctrl_transfer", {"handle": 1, "bmRequestType": "in"}), ("hello", {"session": None})):
            assert "usb_error" in peer.call(op, **args)[0], op
        assert "value" in peer.call("enumerate_devices")[0]
        peer.close()


def test_a_half_sent_request_and_a_silent_idle_peer_are_dropped() -> None:
    with UsbTcpServer(_camera_bus(), request_timeout_s=0.3, idle_timeout_s=0.6) as server:
        half = RawClient(server.port)
        half.sock.sendall(HEAD.pack(100, 0) + b"{")
        idle = RawClient(server.port)
        assert half.closed_within(3.0)
        assert idle.closed_within(3.0)
        half.close()
        idle.close()


def test_a_flood_of_connections_is_capped() -> None:
    with UsbTcpServer(_camera_bus(), max_connections=4) as server:
        peers = [RawClient(server.port) for _ in range(4)]
        for peer in peers:
            peer.call("hello", session=None)
        extra = RawClient(server.port)
        assert extra.closed_within(3.0) and server.refused_connections == 1
        assert "value" in peers[0].call("enumerate_devices")[0]
        for peer in [*peers, extra]:
            peer.close()


@contextmanager
def fake_server(answer: Callable[[socket.socket], None]) -> Iterator[int]:
    """A server that accepts connections and runs ``answer`` on each (until closed); yields its port."""
    listener = socket.create_server(("127.0.0.1", 0))
    listener.settimeout(0.1)
    stop = threading.Event()
    threads: list[threading.Thread] = []

    def serve() -> None:
        while not stop.is_set():
            try:
                conn, _ = listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            thread = threading.Thread(target=_run, args=(conn,))
            threads.append(thread)
            thread.start()

    def _run(conn: socket.socket) -> None:
        with conn:
            conn.settimeout(0.1)
            try:
                answer(conn)
            except OSError:
                pass

    acceptor = threading.Thread(target=serve)
    acceptor.start()
    try:
        yield listener.getsockname()[1]
    finally:
        stop.set()
        acceptor.join(5.0)
        listener.close()
        for thread in threads:
            thread.join(5.0)


def _silent(conn: socket.socket, stop_after_s: float = 8.0) -> None:
    deadline = time.monotonic() + stop_after_s
    while time.monotonic() < deadline:
        try:
            if conn.recv(4096) == b"":
                return
        except TimeoutError:
            continue


def _answers(replies: dict[str, object], payload: bytes = b"") -> Callable[[socket.socket], None]:
    """A server that answers each operation with ``replies[op]`` and ``payload`` (hello with a session)."""
    def answer(conn: socket.socket) -> None:
        buffer, deadline = b"", time.monotonic() + 8.0
        while time.monotonic() < deadline:
            try:
                chunk = conn.recv(4096)
            except TimeoutError:
                continue
            if not chunk:
                return
            buffer += chunk
            while len(buffer) >= 8:
                size, data_size = HEAD.unpack(buffer[:8])
                if len(buffer) < 8 + size + data_size:
                    break
                op = json.loads(buffer[8:8 + size])["op"]
                buffer = buffer[8 + size + data_size:]
                reply = {"value": "s" * 32} if op == "hello" else replies.get(op, {"value": None})
                body, data = json.dumps(reply).encode(), b"" if op == "hello" else payload
                conn.sendall(HEAD.pack(len(body), len(data)) + body + data)
    return answer


def test_a_server_that_never_answers_is_a_device_error_within_the_timeouts() -> None:
    with fake_server(_silent) as port:
        start = time.monotonic()
        with pytest.raises(DeviceError):
            U3VCamera.open(backend=UsbTcpBackend("127.0.0.1", port, io_timeout_s=0.5), timeout_s=0.5)
        assert time.monotonic() - start < 4.0  # a few io timeouts, never the 40 s it took


@pytest.mark.parametrize("enumeration", [
    {"value": 5}, {"value": [[1, {"bLength": "x", "bDescriptorType": 1}]]}, {"value": [[1]]},
    {"usb_error": "broken"}, {"value": 1, "usb_error": [1, 2, 3]}, ["not", "an", "object"],
])
def test_malformed_replies_are_device_errors_not_crashes(enumeration: object) -> None:
    with fake_server(_answers({"enumerate_devices": enumeration})) as port:
        with pytest.raises(DeviceError):
            U3VCamera.open(backend=UsbTcpBackend("127.0.0.1", port, io_timeout_s=0.5), timeout_s=0.5)


def test_a_read_answered_with_more_than_it_asked_is_an_io_error() -> None:
    import array
    import errno as errnos

    import usb.core

    with fake_server(_answers({"bulk_read": {"value": 8}}, payload=b"x" * 8)) as port:
        backend = UsbTcpBackend("127.0.0.1", port, io_timeout_s=0.5)
        with pytest.raises(usb.core.USBError) as raised:  # 4 bytes asked for, 8 sent
            backend.bulk_read(1, 0x81, 1, array.array("B", bytes(4)), 100)
        assert raised.value.errno == errnos.EIO
        backend.close()


def test_run_against_a_silent_camera_server_exits_3(tmp_path: Path, capsys) -> None:
    with fake_server(lambda conn: _silent(conn, stop_after_s=30.0)) as port:
        config = tmp_path / "silent-camera.toml"
        config.write_text(textwrap.dedent(f"""
            [station]
            wavelength_nm = 632.8
            [processing]
            method = "carrier"
            [camera]
            url = "usbtcp://127.0.0.1:{port}"
            timeout_s = 1.0
        """))
        start = time.monotonic()
        assert main(["run", "--config", str(config), "--duration", "5"]) == EXIT_DEVICE_ERROR
        assert time.monotonic() - start < 15.0  # the camera's timeouts, not the server's 30 s of silence
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "camera" in err.lower()
