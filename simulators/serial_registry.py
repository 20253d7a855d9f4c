"""Make pyserial's ``serial_for_url`` reach the simulated serial devices (``sim://``).

pyserial finds a URL handler by importing ``<package>.protocol_<scheme>`` for each package in the
module-level list ``serial.protocol_handler_packages``, and builds the port from the URL string
alone. Two consequences:

* Registration changes pyserial's global list, so it is explicit: call
  :func:`register_serial_simulators` (tests, the station when configured for simulation). Importing a
  driver never does it.
* A URL cannot carry an object, so a test that wants to reach the very device model a port talks to
  (to set faults, read ground truth) must find it by name. This module therefore holds the one
  process-wide registry, ``sim://mdt693b/NAME`` -> device, that pyserial's URL API forces on us; it is
  filled only inside :func:`attach_simulated_device` and emptied on exit.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TypeVar

import serial

HANDLER_PACKAGE = "wavestack.simulators"

Device = TypeVar("Device")


class _NamedDevices:
    """Name -> simulated device, guarded by a lock (pyserial may open ports from any thread)."""

    def __init__(self) -> None:
        self._devices: dict[str, object] = {}
        self._lock = threading.Lock()

    def add(self, name: str, device: object) -> None:
        with self._lock:
            if name in self._devices:
                raise ValueError(f"a simulated device named {name!r} is already attached")
            self._devices[name] = device

    def remove(self, name: str, device: object) -> None:
        with self._lock:
            if self._devices.get(name) is device:
                del self._devices[name]

    def get(self, name: str) -> object | None:
        with self._lock:
            return self._devices.get(name)


# The one registry pyserial's URL API forces on us (see the module docstring).
_NAMED = _NamedDevices()


def register_serial_simulators() -> None:
    """Let ``serial.serial_for_url`` open ``sim://`` URLs; idempotent."""
    if HANDLER_PACKAGE not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(HANDLER_PACKAGE)


@contextmanager
def attach_simulated_device(name: str, device: Device) -> Iterator[Device]:
    """Make ``device`` the one behind ``sim://<model>/<name>`` while the block runs.

    Parameters
    ----------
    name
        Letters, digits, ``-`` and ``_``.
    device
        The device model (e.g. :class:`~wavestack.simulators.mdt693b.MDT693BDevice`).

    Yields
    ------
    The same device, for ``with attach_simulated_device("bench", MDT693BDevice()) as device:``.

    Raises
    ------
    ValueError
        A bad name, or the name is taken.
    """
    if not name or not all(c.isalnum() or c in "-_" for c in name):
        raise ValueError(f"device name must be letters, digits, '-' or '_', got {name!r}")
    _NAMED.add(name, device)
    try:
        yield device
    finally:
        _NAMED.remove(name, device)


def find_simulated_device(name: str) -> object | None:
    """The device attached under ``name``, or None."""
    return _NAMED.get(name)
