"""Test fixture: a minimal scripted PI GCS 2.0 controller on 127.0.0.1 (NOT the simulator).

``FakeGcsController`` answers per PI's wire rules, as far as the driver's unit tests need them
(multi-line replies with a space before every LF but the last; ``#5`` ``#7`` ``#24`` without LF,
answered at once; ``ERR?`` returns and clears the last error; no answer to a refused query). It
moves instantly unless ``hold_motion`` is set. It never imports the driver. The real
end-to-end tests run against the hexapod simulator (``wavestack.simulators.pi_gcs``).
"""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator

import pytest

HEX_AXES = ("X", "Y", "Z", "U", "V", "W")
HEX_TRAVEL = {"X": (-17.0, 17.0), "Y": (-16.0, 16.0), "Z": (-6.5, 6.5),
              "U": (-14.5, 14.5), "V": (-14.5, 14.5), "W": (-25.0, 25.0)}


class FakeGcsController:
    """Scripted controller: state in plain attributes, every received command kept in ``received``."""

    def __init__(self, axes: tuple[str, ...] = HEX_AXES, travel: dict | None = None,
                 idn: str = "(c)2024 Physik Instrumente (PI) GmbH & Co. KG, C-887, 0, 1.0.0") -> None:
        self.axes = axes
        self.travel = dict(travel or HEX_TRAVEL)
        self.idn, self.csv = idn, "2.0"
        self.pos = {a: 0.0 for a in axes}
        self.target = dict(self.pos)
        self.servo = {a: True for a in axes}
        self.referenced = {a: True for a in axes}
        self.pivot = {"R": 0.0, "S": 0.0, "T": 0.0}
        self.velocity = 1.0
        self.error = 0
        self.hold_motion = False  # True: targets are not reached (ONT? 0, #5 reports moving)
        self.busy = False  # #7 answers 0xB0
        self.mute = False  # no answer to anything
        self.received: list[str] = []  # lines and single-byte commands ("#5", "#7", "#24") in order
        self.packets: list[bytes] = []  # raw chunks as received
        self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._server.bind(("127.0.0.1", 0))
        self._server.listen(1)
        self._server.settimeout(0.05)
        self.port = self._server.getsockname()[1]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="fake-gcs-controller", daemon=True)

    @property
    def url(self) -> str:
        return f"tcp://127.0.0.1:{self.port}"

    def __enter__(self) -> FakeGcsController:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(5.0)
        self._server.close()

    # --------------------------------------------------------------------------- serving
    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._server.accept()
            except TimeoutError:
                continue
            with conn:
                conn.settimeout(0.05)
                buffer = b""
                while not self._stop.is_set():
                    try:
                        data = conn.recv(4096)
                    except TimeoutError:
                        continue
                    except OSError:
                        break
                    if not data:
                        break
                    self.packets.append(data)
                    buffer = self._handle(buffer + data, conn)

    def _handle(self, buffer: bytes, conn: socket.socket) -> bytes:
        while buffer:
            if buffer[0] in (5, 7, 24):
                self.received.append(f"#{buffer[0]}")
                reply = self._single(buffer[0])
                buffer = buffer[1:]
            else:
                end = buffer.find(b"\n")
                if end < 0:
                    return buffer
                line, buffer = buffer[:end].decode("ascii"), buffer[end + 1:]
                self.received.append(line)
                reply = self._line(line.split())
            if reply is not None and not self.mute:
                conn.sendall(reply)
        return buffer

    def _single(self, byte: int) -> bytes | None:
        if byte == 5:
            mask = sum(1 << i for i, a in enumerate(self.axes) if self.pos[a] != self.target[a])
            return f"{mask:X}\n".encode()
        if byte == 7:
            return bytes([0xB0 if self.busy else 0xB1]) + b"\n"
        self.target = dict(self.pos)  # #24: stop, error 10, no answer
        self.error = 10
        return None

    @staticmethod
    def _lines(lines: list[str]) -> bytes:
        return (" \n".join(lines) + "\n").encode("ascii")

    def _fail(self, code: int) -> None:
        self.error = self.error or code

    def _line(self, words: list[str]) -> bytes | None:  # noqa: C901 - one dispatch table, kept flat
        cmd, args = (words[0], words[1:]) if words else ("", [])
        if cmd == "ERR?":
            code, self.error = self.error, 0
            return f"{code}\n".encode()
        if cmd == "*IDN?":
            return f"{self.idn}\n".encode()
        if cmd == "CSV?":
            return f"{self.csv}\n".encode()
        if cmd == "SAI?":
            return self._lines(list(self.axes))
        if cmd == "VLS?":
            return f"{self.velocity}\n".encode()
        if cmd == "SPI?":
            return self._lines([f"{k}={v:.6f}" for k, v in self.pivot.items()])
        tables = {"POS?": self.pos, "ONT?": {a: int(self.pos[a] == self.target[a]) for a in self.axes},
                  "TMN?": {a: lo for a, (lo, _) in self.travel.items()},
                  "TMX?": {a: hi for a, (_, hi) in self.travel.items()},
                  "SVO?": {a: int(v) for a, v in self.servo.items()},
                  "FRF?": {a: int(v) for a, v in self.referenced.items()}}
        if cmd in tables:
            axes = args or list(self.axes)
            if any(a not in self.axes for a in axes):
                self._fail(15)
                return None
            return self._lines([f"{a}={tables[cmd][a]}" for a in axes])
        pairs = dict(zip(args[::2], args[1::2]))
        if cmd == "MOV":
            if any(a not in self.axes for a in pairs):
                self._fail(15)
            elif not all(self.servo[a] and self.referenced[a] for a in pairs):
                self._fail(5)
            elif not all(self.travel[a][0] <= float(v) <= self.travel[a][1] for a, v in pairs.items()):
                self._fail(7)
            else:
                self.target.update({a: float(v) for a, v in pairs.items()})
                if not self.hold_motion:
                    self.pos.update(self.target)
        elif cmd == "HLT":
            self.target = dict(self.pos)
            self.error = 10
        elif cmd == "SVO":
            self.servo.update({a: v == "1" for a, v in pairs.items()})
        elif cmd == "SPI":
            if any(self.pos[a] != 0.0 for a in ("U", "V", "W") if a in self.pos):
                self._fail(9)
            else:
                self.pivot.update({a: float(v) for a, v in pairs.items()})
        elif cmd == "VLS":
            self.velocity = float(args[0])
        else:
            self._fail(2)
        return None


@pytest.fixture
def fake_controller() -> Iterator[type[FakeGcsController]]:
    """The fixture's class; use it as a context manager so its thread and socket are closed."""
    yield FakeGcsController
