"""Reading and writing GenICam feature registers of a USB3 Vision camera over its control channel.

The feature's :class:`~wavestack.drivers.u3v.genicam.Register` (from the device's XML) says where
the value lives and how it is encoded: little-endian unsigned integers of the register's length,
or IEEE-754 floats of 4 or 8 bytes.
"""

from __future__ import annotations

import struct

from wavestack.drivers.errors import ProtocolError
from wavestack.drivers.u3v.control import ControlChannel
from wavestack.drivers.u3v.genicam import Feature


def read_feature(control: ControlChannel, feature: Feature, deadline: float, device: str) -> int | float:
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
    int or float
        The register's value (float for float registers).

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
    if reg.is_float:
        return struct.unpack("<f" if reg.length == 4 else "<d", raw)[0]
    return int.from_bytes(raw, "little")


def write_feature(control: ControlChannel, feature: Feature, value: int | float, deadline: float,
                  device: str) -> None:
    """Write a feature's value (or a command's value) to the device.

    Parameters
    ----------
    control
        The camera's control channel.
    feature
        The feature, as resolved from the device's XML.
    value
        The value in the feature's units (packed as the register's type).
    deadline
        ``time.monotonic()`` value by which the write must be acknowledged, s.
    device
        Device name for messages.

    Raises
    ------
    ValueError
        An integer value does not fit the register (nothing sent).
    ProtocolError
        The XML declares the register read-only, or the device refused the write.
    DeviceTimeout, DeviceDisconnected
        As for :meth:`ControlChannel.write`.
    """
    reg = feature.register
    if not reg.writable:
        raise ProtocolError(device, f"feature {feature.name} is read-only per the device's XML")
    if reg.is_float:
        data = struct.pack("<f" if reg.length == 4 else "<d", float(value))
    else:
        if not 0 <= int(value) < 1 << (8 * reg.length):
            raise ValueError(f"{feature.name} = {value} does not fit a {reg.length}-byte unsigned register")
        data = int(value).to_bytes(reg.length, "little")
    control.write(reg.address, data, deadline, feature.name)
