"""Reading and writing GenICam feature registers of a USB3 Vision camera over its control channel.

The feature's :class:`~wavestack.drivers.u3v.genicam.Register` (from the device's XML) says where
the value lives and how it is encoded: little-endian unsigned integers of the register's length,
IEEE-754 floats of 4 or 8 bytes, or (string features) ASCII padded with NUL to the register's length.
"""

from __future__ import annotations

import logging
import struct

from wavestack.drivers.errors import DeviceError, ProtocolError
from wavestack.drivers.u3v.control import ControlChannel
from wavestack.drivers.u3v.genicam import Feature, FeatureMap

logger = logging.getLogger(__name__)


def read_feature(control: ControlChannel, feature: Feature, deadline: float, device: str) -> int | float | str:
    """Read a feature's value from the device.

    Parameters
    ----------
    control
        The camera's control channel.
    feature
        The feature, as resolved from the device's XML.
    deadline
        ``time.monotonic()`` value by which the read must be acknowledged, s.
    device
        Device name for messages.

    Returns
    -------
    int, float or str
        The register's value (float for float registers, the text up to the first NUL for strings).

    Raises
    ------
    ProtocolError
        The XML declares the register write-only, or the device refused the read.
    DeviceTimeout, DeviceDisconnected
        As for :meth:`ControlChannel.read`.
    """
    name = feature.name
    reg = feature.register
    if not reg.readable:
        raise ProtocolError(device, f"feature {name} is write-only per the device's XML")
    raw = control.read(reg.address, reg.length, deadline, name)
    if feature.kind == "string":
        return raw.split(b"\0", 1)[0].decode("ascii", "replace")
    if reg.is_float:
        return struct.unpack("<f" if reg.length == 4 else "<d", raw)[0]
    return int.from_bytes(raw, "little")


def write_feature(control: ControlChannel, feature: Feature, value: int | float | str, deadline: float,
                  device: str) -> None:
    """Write a feature's value (or a command's value) to the device.

    Parameters
    ----------
    control
        The camera's control channel.
    feature
        The feature, as resolved from the device's XML.
    value
        The value in the feature's units (packed as the register's type); ASCII text for a string.
    deadline
        ``time.monotonic()`` value by which the write must be acknowledged, s.
    device
        Device name for messages.

    Raises
    ------
    ValueError
        An integer value or a text does not fit the register, or a text is not ASCII (nothing sent).
    ProtocolError
        The XML declares the register read-only, or the device refused the write.
    DeviceTimeout, DeviceDisconnected
        As for :meth:`ControlChannel.write`.
    """
    reg = feature.register
    if not reg.writable:
        raise ProtocolError(device, f"feature {feature.name} is read-only per the device's XML")
    if feature.kind == "string":
        text = str(value).encode("ascii") if str(value).isascii() else None
        if text is None or len(text) > reg.length or b"\0" in text:
            raise ValueError(f"{feature.name} = {value!r}: expected ASCII text of at most {reg.length} characters")
        data = text.ljust(reg.length, b"\0")
    elif reg.is_float:
        data = struct.pack("<f" if reg.length == 4 else "<d", float(value))
    else:
        if not 0 <= int(value) < 1 << (8 * reg.length):
            raise ValueError(f"{feature.name} = {value} does not fit a {reg.length}-byte unsigned register")
        data = int(value).to_bytes(reg.length, "little")
    control.write(reg.address, data, deadline, feature.name)


def lock_transport_layer(control: ControlChannel, features: FeatureMap, deadline: float, device: str) -> None:
    """Before AcquisitionStart, as a GenTL producer does (SFNC): AcquisitionMode Continuous, TLParamsLocked 1.

    Each is skipped when the device's XML does not describe it (or Continuous).

    Raises
    ------
    DeviceTimeout, DeviceDisconnected, ProtocolError
        As for :func:`write_feature`.
    """
    mode = features.features.get("AcquisitionMode")
    if mode is not None and mode.register.writable and "Continuous" in mode.entries:
        write_feature(control, mode, mode.entries["Continuous"], deadline, device)
    if "TLParamsLocked" in features:
        write_feature(control, features.require("TLParamsLocked", device), 1, deadline, device)


def unlock_transport_layer(control: ControlChannel, features: FeatureMap, deadline: float, device: str) -> None:
    """TLParamsLocked back to 0 after the acquisition; best effort (a failure is logged, not raised)."""
    if "TLParamsLocked" not in features:
        return
    try:
        write_feature(control, features.require("TLParamsLocked", device), 0, deadline, device)
    except DeviceError as exc:
        logger.warning("%s: could not clear TLParamsLocked (%s)", device, exc)

