"""Opening a USB3 Vision connection: find the camera, claim its interfaces, read what it is.

:func:`find_device` picks a USB3 Vision device (by interface class) off the bus; :func:`attach`
claims its control and stream interfaces, builds the :class:`~.control.ControlChannel`, reads the
ABRM, SBRM, manifest and GenICam XML, and returns everything as one :class:`Link`, which the
driver replaces as a whole when it reconnects.
"""

from __future__ import annotations

import errno
import hashlib
import logging
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import usb.core
import usb.util

from wavestack.drivers.errors import DeviceDisconnected, ProtocolError
from wavestack.drivers.u3v import bootstrap as bs
from wavestack.drivers.u3v import gencp
from wavestack.drivers.u3v.control import ControlChannel
from wavestack.drivers.genicam import NodeMap
from wavestack.drivers.genicam.camera_features import CameraFeatures
from wavestack.drivers.u3v.register_port import GenCPPort

logger = logging.getLogger(__name__)

U3V_CLASS = 0xEF
U3V_SUBCLASS = 0x05
CONTROL_PROTOCOL = 0x00
STREAM_PROTOCOL = 0x02
_MAX_XML_FILE = 32 << 20


def _u3v_interfaces(dev: usb.core.Device) -> tuple[Any, Any] | None:
    """(control, stream) interface descriptors of a USB3 Vision device, or ``None``."""
    try:
        for cfg in dev:
            control = usb.util.find_descriptor(cfg, bInterfaceClass=U3V_CLASS, bInterfaceSubClass=U3V_SUBCLASS,
                                               bInterfaceProtocol=CONTROL_PROTOCOL)
            stream = usb.util.find_descriptor(cfg, bInterfaceClass=U3V_CLASS, bInterfaceSubClass=U3V_SUBCLASS,
                                              bInterfaceProtocol=STREAM_PROTOCOL)
            if control is not None and stream is not None:
                return control, stream
    except (usb.core.USBError, ValueError, NotImplementedError):
        return None
    return None


def find_device(backend: Any, serial: str | None) -> usb.core.Device | None:
    """The first USB3 Vision device (by interface class) with this serial number (any if ``None``).

    Raises
    ------
    DeviceDisconnected
        pyusb has no backend (libusb is not installed): no camera can be reached.
    """
    try:
        found_devices = list(usb.core.find(find_all=True, backend=backend,
                                           custom_match=lambda d: _u3v_interfaces(d) is not None))
    except usb.core.NoBackendError:
        raise DeviceDisconnected("USB3 Vision camera", "pyusb found no USB backend: expected libusb-1.0 to be "
                                 "installed (e.g. apt install libusb-1.0-0); sim://u3v needs none") from None
    for dev in found_devices:
        if serial is None:
            return dev
        try:
            found = dev.serial_number
        except (usb.core.USBError, ValueError, NotImplementedError):
            found = None
        if found == serial:
            return dev
        usb.util.dispose_resources(dev)
    return None


def _endpoint(interface: Any, direction: int) -> int:
    ep = usb.util.find_descriptor(
        interface, custom_match=lambda e: usb.util.endpoint_direction(e.bEndpointAddress) == direction
        and usb.util.endpoint_type(e.bmAttributes) == usb.util.ENDPOINT_TYPE_BULK)
    if ep is None:
        raise ProtocolError("U3V camera", f"interface {interface.bInterfaceNumber} lacks a bulk "
                                          f"{'IN' if direction == usb.util.ENDPOINT_IN else 'OUT'} endpoint")
    return int(ep.bEndpointAddress)


@dataclass(frozen=True)
class Link:
    """What one connection to the device consists of (replaced as a whole by ``reopen``)."""

    dev: usb.core.Device
    interfaces: tuple[int, int]
    stream_ep: int
    control: ControlChannel
    abrm: bs.Abrm
    sbrm: bs.Sbrm
    features: CameraFeatures


def attach(dev: usb.core.Device, deadline: float, device: str,
           on_disconnect: Callable[[DeviceDisconnected], None]) -> Link:
    """Claim a USB3 Vision device and read its bootstrap registers and GenICam XML.

    Parameters
    ----------
    dev
        The device, as found by :func:`find_device`.
    deadline
        ``time.monotonic()`` value by which the whole sequence must be done, s.
    device
        Device name for messages.
    on_disconnect
        Called by the control channel when it finds the device gone.

    Returns
    -------
    Link
        The claimed interfaces, stream endpoint, control channel, ABRM, SBRM and features.

    Raises
    ------
    DeviceDisconnected
        The device vanished while being claimed.
    DeviceTimeout, ProtocolError
        The device did not answer in time or answered outside the protocol (e.g. no stream
        channel, an unusable manifest, or a required feature missing from the XML).
    """
    interfaces = _u3v_interfaces(dev)
    if interfaces is None:
        raise ProtocolError(device, "device lost its USB3 Vision interfaces")
    control_intf, stream_intf = interfaces
    try:
        try:
            dev.get_active_configuration()
        except usb.core.USBError:
            dev.set_configuration()
        for intf in (control_intf, stream_intf):
            usb.util.claim_interface(dev, intf.bInterfaceNumber)
    except usb.core.USBError as exc:
        if exc.errno == errno.ENODEV:
            raise DeviceDisconnected(device, f"device vanished while claiming it: {exc}") from None
        raise ProtocolError(device, f"could not claim the USB3 Vision interfaces: {exc}") from None
    control = ControlChannel(dev, _endpoint(control_intf, usb.util.ENDPOINT_OUT),
                             _endpoint(control_intf, usb.util.ENDPOINT_IN), device, on_disconnect)
    response_ms = struct.unpack("<I", control.read(bs.ABRM_MAX_RESPONSE_TIME, 4, deadline, "ABRM"))[0]
    control.response_time_s = response_ms / 1000 if response_ms > 0 else None
    abrm = bs.decode_abrm(control.read(bs.ABRM_ADDRESS, bs.ABRM_SIZE, deadline, "ABRM"), device)
    sbrm = bs.decode_sbrm(control.read(abrm.sbrm_address, bs.SBRM_SIZE, deadline, "SBRM"), device)
    try:
        control.read_chunk = gencp.max_read_chunk(sbrm.max_ack_transfer_length)
        control.write_chunk = gencp.max_write_chunk(sbrm.max_command_transfer_length)
    except ValueError as exc:
        raise ProtocolError(device, f"SBRM transfer lengths: {exc}") from None
    control.ack_buffer = gencp.ack_buffer_size(sbrm.max_ack_transfer_length)  # a u32: never 4 GiB per read
    if sbrm.stream_channel_count < 1:
        raise ProtocolError(device, "SBRM reports no stream channel; expected one")
    features = _read_features(control, abrm, deadline, device)
    features.require()
    return Link(dev, (control_intf.bInterfaceNumber, stream_intf.bInterfaceNumber),
                _endpoint(stream_intf, usb.util.ENDPOINT_IN), control, abrm, sbrm, features)


def release(link: Link, device: str) -> None:
    """Release the claimed interfaces and the USB resources of a connection (errors are logged).

    Parameters
    ----------
    link
        The connection to give up.
    device
        Device name for messages.
    """
    for number in link.interfaces:
        try:
            usb.util.release_interface(link.dev, number)
        except (usb.core.USBError, ValueError) as exc:
            logger.debug("%s: release_interface(%d): %s", device, number, exc)
    try:
        usb.util.dispose_resources(link.dev)
    except usb.core.USBError as exc:
        logger.debug("%s: dispose_resources: %s", device, exc)

def _read_features(control: ControlChannel, abrm: bs.Abrm, deadline: float, device: str) -> CameraFeatures:
    """The node map of the GenICam file the manifest's first entry points at (SHA-1 checked), on the
    control channel."""
    table = abrm.manifest_table_address
    if bs.decode_manifest_count(control.read(table, bs.MANIFEST_COUNT_SIZE, deadline, "manifest"), device) < 1:
        raise ProtocolError(device, "manifest table is empty; expected a GenICam XML entry")
    entry = bs.decode_manifest_entry(
        control.read(table + bs.MANIFEST_COUNT_SIZE, bs.MANIFEST_ENTRY_SIZE, deadline, "manifest"), device)
    if entry.file_format not in (bs.MANIFEST_FORMAT_XML, bs.MANIFEST_FORMAT_ZIP):
        raise ProtocolError(device, f"manifest file format {entry.file_format}; expected 0 (XML) or 1 (ZIP)")
    if not 0 < entry.size <= _MAX_XML_FILE:
        raise ProtocolError(device, f"GenICam file size {entry.size} B; expected 1..{_MAX_XML_FILE} B")
    data = control.read(entry.address, entry.size, deadline, "GenICam file")
    if any(entry.sha1) and hashlib.sha1(data).digest() != entry.sha1:
        raise ProtocolError(device, "GenICam file does not match the manifest's SHA-1")
    node_map = NodeMap.from_xml(data, device=device, zipped=entry.file_format == bs.MANIFEST_FORMAT_ZIP)
    port = GenCPPort(control)
    node_map.attach(port)
    return CameraFeatures(node_map, port)
