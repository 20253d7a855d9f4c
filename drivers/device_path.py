"""Which local device paths a driver may open: serial ports and terminals under ``/dev``, nothing else.

A device URL of kind ``device`` is opened read-write by the serial driver, so a path that only
*looks* like a device (``/dev/../home/user/file``, or a symlink under ``/dev`` pointing at a
file) would let a configuration overwrite any file the user can write. The path is therefore
resolved first (:func:`os.path.realpath`: ``..`` removed and every symlink followed) and the
*resolved* path is checked against the allow-list.

Allowed device paths
--------------------
- ``COMn`` (Windows serial ports), taken as written.
- Any absolute path under ``/dev`` whose resolved path is a serial port or terminal:
  ``/dev/tty<name>`` (``ttyUSB0``, ``ttyACM0``, ``ttyS0``, macOS ``tty.usbserial-...``),
  ``/dev/cu.<name>`` (macOS call-out ports) or ``/dev/pts/<n>`` (a pseudo-terminal, e.g. the
  one ``wavestack sim pzt`` serves). Stable names such as ``/dev/serial/by-id/usb-...`` and udev
  symlinks such as ``/dev/piezo`` are allowed when they resolve into one of these.
- A path that does not exist (yet) on this machine resolves to itself; it is allowed when it
  is itself of one of the forms above or ``/dev/serial/by-id/<name>`` / ``/dev/serial/by-path/<name>``
  (a configuration may be checked on a machine without the device).

Refused: ``/dev/tty`` itself (the controlling terminal), any other ``/dev`` node (disks,
``/dev/null``, ``/dev/shm/...``), and any path that resolves outside ``/dev``.

The configuration checks the path when it is loaded and keeps it as written (a by-id name
survives a replug that renames ``ttyUSB0``); the MDT693B driver checks it again just before it
opens the port, since a symlink may change in between, and code that builds a driver without a
configuration gets the same check.
"""

from __future__ import annotations

import os
import re
from typing import Final

__all__ = ["DEVICE_PATH_RULE", "check_device_path", "is_device_path"]

#: What the allow-list accepts, for error messages.
DEVICE_PATH_RULE: Final = ("a serial port or terminal under /dev (/dev/tty*, /dev/cu.*, /dev/pts/N, or a "
                           "/dev/serial/by-id/* or other /dev symlink resolving to one), or COMn")

_COM_PORT = re.compile(r"^COM\d{1,3}$")
_WRITTEN = re.compile(r"^/dev/\S+$")
_SERIAL_NODE = r"(tty[^/\s]+|cu\.[^/\s]+|pts/\d+)"
_STABLE_NAME = r"serial/by-(id|path)/[^/\s]+"


def is_device_path(url: str) -> bool:
    """True when ``url`` is written as a local device path (``/dev/...`` or ``COMn``), allowed or not."""
    return bool(_COM_PORT.match(url) or _WRITTEN.match(url))


def check_device_path(url: str, *, dev: str = "/dev") -> str | None:
    """Why ``url`` is not an allowed device path, or None when it is (module notes).

    Parameters
    ----------
    url : str
        The path as written in the configuration.
    dev : str
        The device directory (``/dev``; tests pass a temporary directory laid out like one).

    Returns
    -------
    str or None
        A short reason naming the resolved path, or None for an allowed path.
    """
    if _COM_PORT.match(url):
        return None
    if not _WRITTEN.match(url) or "\x00" in url:
        return f"expected {DEVICE_PATH_RULE}"
    dev = os.path.realpath(dev)
    resolved = os.path.realpath(os.path.join(dev, url[len("/dev/"):]))
    node = re.compile(rf"^{re.escape(dev)}/{_SERIAL_NODE}$")
    if node.match(resolved):
        return None
    if not os.path.lexists(resolved) and re.match(rf"^{re.escape(dev)}/{_STABLE_NAME}$", resolved):
        return None
    shown = resolved if dev == "/dev" or not resolved.startswith(dev + "/") else "/dev" + resolved[len(dev):]
    return f"resolves to {shown!r}, which is not {DEVICE_PATH_RULE}"
