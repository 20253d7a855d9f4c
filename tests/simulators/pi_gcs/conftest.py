"""Fixtures for the GCS simulator's tests: a hand-moved clock, a plain-socket GCS client, servers.

The client below is written for the tests from the wire rule alone (an answer ends at an LF not
preceded by a space); it shares nothing with the simulator or the driver.
"""

from __future__ import annotations

import socket
from collections.abc import Callable, Iterator
from contextlib import ExitStack

import pytest

from wavestack.simulators.pi_gcs import HexapodSimSettings, HexapodSimulator

_FIELD_STAGE = HexapodSimSettings(axes=("X", "Y"), low_limits=(-40.0, -30.0), high_limits=(40.0, 30.0),
                                 velocity=5.0, pivot=None, idn="PI C-884 field stage (simulated)")


class ManualClock:
    """A clock that moves only when told (simulated seconds)."""

    def __init__(self, start: float = 1000.0) -> None:
        self.now = start

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += seconds


class Link:
    """A bare TCP client: send bytes, read complete GCS answers."""

    def __init__(self, port: int, timeout_s: float = 5.0) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout_s)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.buffer = b""

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def reply(self) -> bytes:
        """The next complete answer: bytes up to the first LF whose previous byte is not a space."""
        while True:
            for index, byte in enumerate(self.buffer):
                if byte == 0x0A and (index == 0 or self.buffer[index - 1] != 0x20):
                    answer, self.buffer = self.buffer[:index + 1], self.buffer[index + 1:]
                    return answer
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError(f"connection closed; unfinished answer {self.buffer!r}")
            self.buffer += chunk

    def ask(self, command: str) -> str:
        self.send(command.encode("latin-1") + b"\n")
        return self.reply().decode("latin-1")

    def values(self, command: str) -> dict[str, str]:
        """``AXIS=value`` lines of an answer as a dict."""
        lines = self.ask(command).rstrip("\n").split(" \n")
        return dict(line.split("=", 1) for line in lines)

    def error(self) -> int:
        return int(self.ask("ERR?"))

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def field_stage() -> HexapodSimSettings:
    """The bench's two-axis field stage: the same simulator with axes X Y and no pivot."""
    return _FIELD_STAGE


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock()


@pytest.fixture
def serve() -> Iterator[Callable[..., HexapodSimulator]]:
    """Start simulators (``serve(settings, clock=...)``); all are stopped when the test ends."""
    with ExitStack() as stack:
        def start(settings: HexapodSimSettings | None = None, **kwargs: object) -> HexapodSimulator:
            return stack.enter_context(HexapodSimulator(settings or HexapodSimSettings(), **kwargs))  # type: ignore[arg-type]
        yield start


@pytest.fixture
def connect() -> Iterator[Callable[[HexapodSimulator], Link]]:
    """Open plain-socket links to a simulator; all are closed when the test ends."""
    links: list[Link] = []

    def open_link(simulator: HexapodSimulator) -> Link:
        links.append(Link(simulator.port))
        return links[-1]
    yield open_link
    for link in links:
        link.close()
