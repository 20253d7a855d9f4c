"""pyserial URL handler for ``sim://``: a serial port whose far end is a simulated device.

pyserial imports this module as ``wavestack.simulators.protocol_sim`` once
:func:`~wavestack.simulators.serial_registry.register_serial_simulators` has added
``"wavestack.simulators"`` to ``serial.protocol_handler_packages``. URL form::

    sim://mdt693b[/NAME][?echo=0&prompt=*&vlimit=100&cm=1]
    sim://mdt694b[...]                                 the one-axis model
    sim://mdt693a[...]                                 the older MDT693A (its command set only)

Without ``NAME`` every open gets a fresh device with the personality the query describes (defaults:
echo on, prompt ``>``, limit switch at 150 V, MDT693A compatibility mode off). With ``NAME`` the port talks to the device attached
under that name with :func:`~wavestack.simulators.serial_registry.attach_simulated_device` (its
personality is its own, so a query is refused).

The port behaves like a real one where a driver can tell: ``read`` returns fewer bytes when
``timeout`` expires, replies that the device splits arrive in pieces at their scheduled times, and an
unplugged device makes ``open``, ``read`` and ``write`` raise :class:`serial.SerialException`. No
thread is started.
"""

from __future__ import annotations

import threading
import time
import urllib.parse
from collections import deque
from typing import Any

from serial.serialutil import PortNotOpenError, SerialBase, SerialException, to_bytes

from wavestack.simulators.mdt693b import MDT693BDevice, MDT693BPersonality
from wavestack.simulators.serial_registry import find_simulated_device

_MODELS = {"mdt693b": "MDT693B", "mdt694b": "MDT694B", "mdt693a": "MDT693A"}
_POLL_S = 0.02  # how often a blocked read looks at the unplugged switch
_URL_FORM = "sim://mdt693b[/NAME][?echo=0|1&prompt=>|*&vlimit=75|100|150&cm=0|1]"


class Serial(SerialBase):
    """A serial port connected to a simulated device (see the module docstring)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._device: MDT693BDevice | None = None
        self._inbox = bytearray()
        self._pending: deque[tuple[float, bytes]] = deque()  # (monotonic release time, chunk)
        self._last_release = 0.0
        self._changed = threading.Condition()
        self._cancelled = False
        super().__init__(*args, **kwargs)

    # ---------------------------------------------------------------------------- lifecycle
    def open(self) -> None:
        """Connect to the device the URL names; :class:`SerialException` if it cannot."""
        if self.is_open:
            raise SerialException("Port is already open.")
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        device = device_for_url(self._port)
        if device.faults.unplugged:
            raise SerialException(f"could not open port {self._port}: simulated device is unplugged")
        with self._changed:
            self._device = device
            self._inbox.clear()
            self._pending.clear()
            self._last_release = 0.0
        self.is_open = True

    def close(self) -> None:
        """Disconnect; idempotent. The device keeps its state (a named one can be reopened)."""
        with self._changed:
            self.is_open = False
            self._device = None
            self._inbox.clear()
            self._pending.clear()
            self._changed.notify_all()

    def _reconfigure_port(self) -> None:
        """Baud rate and framing mean nothing to a simulated wire."""

    # ----------------------------------------------------------------------------- the wire
    @property
    def in_waiting(self) -> int:
        """Bytes that have arrived and not been read."""
        with self._changed:
            self._connected()
            self._release()
            return len(self._inbox)

    @property
    def out_waiting(self) -> int:
        """Always 0: the device takes written bytes at once."""
        return 0

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes; fewer if ``timeout`` expires first (None blocks, 0 polls)."""
        timeout = self._timeout
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._changed:
            self._cancelled = False
            while True:
                self._connected()
                self._release()
                if len(self._inbox) >= size or self._cancelled:
                    break
                now = time.monotonic()
                if deadline is not None and now >= deadline:
                    break
                wait = _POLL_S
                if deadline is not None:
                    wait = min(wait, deadline - now)
                if self._pending:
                    wait = min(wait, max(0.0, self._pending[0][0] - now))
                self._changed.wait(wait)
            data = bytes(self._inbox[:size])
            del self._inbox[:size]
            return data

    def write(self, data: bytes) -> int:
        """Hand ``data`` to the device; its answer is scheduled for reading."""
        with self._changed:
            device = self._connected()
            payload = to_bytes(data)
        reply = device.feed(payload)
        with self._changed:
            if self._device is not device:  # closed while the device worked
                raise PortNotOpenError()
            release = max(time.monotonic(), self._last_release)
            for delay, chunk in device.delivery_plan(reply):
                release += delay
                self._pending.append((release, chunk))
            self._last_release = release
            self._changed.notify_all()
        return len(payload)

    def reset_input_buffer(self) -> None:
        """Discard what has arrived (chunks still on their way keep coming, as on a real port)."""
        with self._changed:
            self._connected()
            self._release()
            self._inbox.clear()

    def reset_output_buffer(self) -> None:
        """Nothing waits to be sent."""
        self._connected_checked()

    def flush(self) -> None:
        """Nothing waits to be sent."""
        self._connected_checked()

    def cancel_read(self) -> None:
        """Make a blocked ``read`` return what it has."""
        with self._changed:
            self._cancelled = True
            self._changed.notify_all()

    def cancel_write(self) -> None:
        """Writes never block."""

    def _update_break_state(self) -> None:
        """No break line on a simulated wire."""

    def _update_rts_state(self) -> None:
        """No RTS line on a simulated wire."""

    def _update_dtr_state(self) -> None:
        """No DTR line on a simulated wire."""

    @property
    def cts(self) -> bool:
        """Clear to send: always."""
        return True

    @property
    def dsr(self) -> bool:
        """Data set ready: always."""
        return True

    @property
    def ri(self) -> bool:
        """Ring indicator: never."""
        return False

    @property
    def cd(self) -> bool:
        """Carrier detect: always."""
        return True

    # ----------------------------------------------------------------------------- internals
    def _connected_checked(self) -> MDT693BDevice:
        with self._changed:
            return self._connected()

    def _connected(self) -> MDT693BDevice:
        """The device, or raise as a real port would (call with the condition held)."""
        device = self._device
        if not self.is_open or device is None:
            raise PortNotOpenError()
        if device.faults.unplugged:
            raise SerialException(f"{self._port}: device reports readiness to read but returned no data "
                                  "(simulated device unplugged)")
        return device

    def _release(self) -> None:
        now = time.monotonic()
        while self._pending and self._pending[0][0] <= now:
            self._inbox += self._pending.popleft()[1]


def device_for_url(url: str) -> MDT693BDevice:
    """The device a ``sim://`` URL names: a fresh one, or the one attached under ``/NAME``.

    Raises
    ------
    SerialException
        Not a ``sim://`` URL of a known model, an unknown option or value, or no device attached
        under the name.
    """
    parts = urllib.parse.urlsplit(url)
    model = _MODELS.get(parts.netloc.lower())
    if parts.scheme.lower() != "sim" or model is None:
        raise SerialException(f"expected a URL of the form {_URL_FORM}, got {url!r}")
    name = parts.path.strip("/")
    try:
        options = urllib.parse.parse_qs(parts.query, keep_blank_values=True, strict_parsing=bool(parts.query))
    except ValueError as error:
        raise SerialException(f"{url!r}: malformed query ({error}); expected {_URL_FORM}") from None
    if name:
        if options:
            raise SerialException(f"{url!r}: a named device has its own personality; drop the query")
        device = find_simulated_device(name)
        if not isinstance(device, MDT693BDevice):
            raise SerialException(f"{url!r}: no simulated {model} attached as {name!r}")
        if device.personality.model != model:
            raise SerialException(f"{url!r}: the device attached as {name!r} is an {device.personality.model}")
        return device
    return MDT693BDevice(_personality(url, model, options))


def _personality(url: str, model: str, options: dict[str, list[str]]) -> MDT693BPersonality:
    allowed = {"echo": ("0", "1"), "prompt": (">", "*"), "vlimit": ("75", "100", "150"), "cm": ("0", "1")}
    for key, values in options.items():
        if key not in allowed or len(values) != 1 or values[0] not in allowed[key]:
            raise SerialException(f"{url!r}: option {key}={values} not understood; expected {_URL_FORM}")
    echo = options.get("echo", ["1"])[0] == "1"
    prompt = options.get("prompt", [">"])[0]
    vlimit = float(options.get("vlimit", ["150"])[0])
    firmware = "3.01" if model == "MDT693A" else "1.10" if prompt == ">" else "1.05"
    return MDT693BPersonality(model=model, echo=echo, prompt=prompt,  # type: ignore[arg-type]
                              firmware=firmware, decimals=2 if prompt == ">" else 1, vlimit_v=vlimit,
                              compatibility_mode=options.get("cm", ["0"])[0] == "1")
