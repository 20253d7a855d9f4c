"""The one byte link: URLs, framed exchanges, every read bounded in size and time, typed errors."""

from __future__ import annotations

import os
import socket
import threading
import time
import tty
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import pytest

from wavestack.drivers.errors import DeviceDisconnected, DeviceTimeout, ProtocolError
from wavestack.drivers.link import ByteLink, line_framing, parse_tcp_url

DEADLINE_S = 0.3


@contextmanager
def peer(behave: Callable[[socket.socket], None]) -> Iterator[int]:
    """A one-connection TCP peer on loopback running ``behave``; yields its port, joins it after."""
    listener = socket.create_server(("127.0.0.1", 0))
    listener.settimeout(5.0)

    def serve() -> None:
        try:
            conn, _ = listener.accept()
        except OSError:
            return
        with conn:
            try:
                behave(conn)
            except OSError:
                pass

    thread = threading.Thread(target=serve)
    thread.start()
    try:
        yield listener.getsockname()[1]
    finally:
        listener.close()
        thread.join(5.0)


def echo_lines(conn: socket.socket) -> None:
    conn.settimeout(5.0)
    while data := conn.recv(4096):
        conn.sendall(data.upper())


def test_an_exchange_returns_the_framed_reply_and_keeps_what_follows() -> None:
    with peer(echo_lines) as port:
        link = ByteLink(f"tcp://127.0.0.1:{port}", lambda: "echo")
        link.open(timeout_s=2.0)
        assert link.exchange(b"a\nb\n", line_framing, time.monotonic() + 2.0, during="a") == b"A\n"
        assert link.receive(line_framing, time.monotonic() + 2.0, during="b") == b"B\n"
        link.close()


def test_a_silent_device_is_a_timeout_at_the_deadline_and_leaves_the_link_dirty() -> None:
    quiet = threading.Event()
    with peer(lambda conn: quiet.wait(5.0)) as port:
        link = ByteLink(f"tcp://127.0.0.1:{port}", lambda: "silent")
        link.open(timeout_s=2.0)
        start = time.monotonic()
        with pytest.raises(DeviceTimeout, match="no complete reply"):
            link.exchange(b"?\n", line_framing, start + DEADLINE_S, during="?")
        # the deadline is kept within one poll (20 ms) plus scheduling on a loaded machine
        assert time.monotonic() - start < DEADLINE_S + 0.5
        assert link.dirty
        quiet.set()
        link.close()


def test_a_flood_without_a_frame_stops_at_the_reply_bound() -> None:
    def flood(conn: socket.socket) -> None:
        conn.settimeout(5.0)
        conn.recv(16)
        chunk = b"x" * 65536
        for _ in range(64):  # 4 MiB at most, never a line end
            conn.sendall(chunk)

    with peer(flood) as port:
        link = ByteLink(f"tcp://127.0.0.1:{port}", lambda: "flood", max_reply_bytes=4096)
        link.open(timeout_s=2.0)
        with pytest.raises(ProtocolError, match="4096 bytes without a complete reply"):
            link.exchange(b"?\n", line_framing, time.monotonic() + 5.0, during="?")
        assert link.dirty
        link.close()


def test_a_closed_connection_is_lost_until_opened_again() -> None:
    with peer(lambda conn: conn.recv(16)) as port:
        link = ByteLink(f"tcp://127.0.0.1:{port}", lambda: "gone")
        link.open(timeout_s=2.0)
        with pytest.raises(DeviceDisconnected, match="closed by the device"):
            link.exchange(b"?\n", line_framing, time.monotonic() + 2.0, during="?")
        assert not link.is_open
        with pytest.raises(DeviceDisconnected, match="lost earlier"):
            link.send(b"?\n", time.monotonic() + 1.0, during="?")


def test_drain_discards_late_bytes_until_quiet() -> None:
    def late(conn: socket.socket) -> None:
        conn.settimeout(5.0)
        conn.recv(16)
        time.sleep(0.1)
        conn.sendall(b"late\n")
        conn.recv(16)
        conn.sendall(b"fresh\n")

    with peer(late) as port:
        link = ByteLink(f"tcp://127.0.0.1:{port}", lambda: "late")
        link.open(timeout_s=2.0)
        with pytest.raises(DeviceTimeout):
            link.exchange(b"1\n", line_framing, time.monotonic() + 0.02, during="1")
        time.sleep(0.2)
        assert link.drain(time.monotonic() + 1.0) == len(b"late\n")
        assert link.exchange(b"2\n", line_framing, time.monotonic() + 2.0, during="2") == b"fresh\n"
        link.close()


def test_pyserial_urls_socket_and_a_pseudo_terminal() -> None:
    with peer(echo_lines) as port:
        link = ByteLink(f"socket://127.0.0.1:{port}", lambda: "socket")
        link.open(timeout_s=2.0)
        assert link.exchange(b"hi\n", line_framing, time.monotonic() + 2.0, during="hi") == b"HI\n"
        link.close()
    master, slave = os.openpty()
    try:
        tty.setraw(slave)
        link = ByteLink(os.ttyname(slave), lambda: "pty")
        link.open(timeout_s=1.0)
        link.send(b"ping\n", time.monotonic() + 1.0, during="ping")
        assert os.read(master, 16) == b"ping\n"
        os.write(master, b"stale\n")
        time.sleep(0.05)
        assert link.exchange(b"q\n", line_framing, time.monotonic() + 0.5, during="q") == b"stale\n"
        link.close()
    finally:
        os.close(master)
        os.close(slave)


def test_a_fresh_exchange_drops_what_arrived_before_it() -> None:
    master, slave = os.openpty()
    try:
        tty.setraw(slave)
        link = ByteLink(os.ttyname(slave), lambda: "pty")
        link.open(timeout_s=1.0)
        os.write(master, b"stale\n")
        time.sleep(0.05)
        with pytest.raises(DeviceTimeout):
            link.exchange(b"q\n", line_framing, time.monotonic() + 0.1, during="q", fresh=True)
        link.close()
    finally:
        os.close(master)
        os.close(slave)


def test_urls() -> None:
    assert parse_tcp_url("tcp://10.0.0.5", 50000) == ("10.0.0.5", 50000)
    assert parse_tcp_url("socket://10.0.0.5:1") is None
    with pytest.raises(ValueError, match="tcp://HOST:PORT"):
        parse_tcp_url("tcp://10.0.0.5")
    with pytest.raises(ValueError, match="port 1..65535"):
        ByteLink("tcp://h:70000", lambda: "x")
    link = ByteLink("/dev/../etc/passwd", lambda: "x")
    with pytest.raises(ValueError, match="refusing to open"):
        link.open(timeout_s=0.1)
