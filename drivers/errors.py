"""Typed device errors: each names the device and says what was expected.

Every driver raises only these (or ``ValueError`` for a bad argument before any I/O), so a station
can tell a slow device from a lost one from a confused one without parsing messages.
"""

from __future__ import annotations


class DeviceError(Exception):
    """Base of every device error.

    Parameters
    ----------
    device
        Who failed, as a user would name it: ``"MDT693B on /dev/ttyUSB0"``, ``"U3V camera 2bdf:0001"``.
    message
        What happened and what was expected.
    """

    def __init__(self, device: str, message: str) -> None:
        super().__init__(f"{device}: {message}")
        self.device = device
        self.detail = message


def renewed(error: DeviceError) -> DeviceError:
    """A new error of ``error``'s type, text and attributes, with no traceback yet.

    For an error kept to be raised again later (a closed frame ring's reason): raising the kept
    object itself grows its traceback at every raise, and that traceback names the frame that
    keeps the object, a reference cycle that holds the callers' locals (frames of images) until
    the cyclic garbage collector happens to run (issue 13's soak).

    Example
    -------
    >>> kept = DeviceDisconnected("camera", "unplugged")
    >>> again = renewed(kept)
    >>> again is not kept and type(again) is DeviceDisconnected and str(again) == str(kept)
    True
    """
    fresh = type(error).__new__(type(error))
    Exception.__init__(fresh, *error.args)
    fresh.__dict__.update(error.__dict__)
    return fresh


class DeviceTimeout(DeviceError, TimeoutError):
    """The device did not answer within the call's timeout."""


class DeviceDisconnected(DeviceError, ConnectionError):
    """The device went away (unplugged, port closed, connection refused or reset)."""


class ProtocolError(DeviceError):
    """The device answered, but not with what the protocol allows at this point."""


class LimitError(DeviceError, ValueError):
    """A requested value lies outside the device's or the configuration's limits; nothing was sent."""
