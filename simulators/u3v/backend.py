"""A pyusb backend whose bus holds simulated USB3 Vision cameras.

``usb.core.find(find_all=True, backend=SimulatedUsbBackend([camera]), ...)`` enumerates the
plugged-in cameras and returns real ``usb.core.Device`` objects; their ``write``/``read``/
``clear_halt``/``ctrl_transfer`` reach the camera. Failures surface as a libusb backend raises them:

=================================  ==================================================
device side                        pyusb
=================================  ==================================================
TransferTimeout                    ``USBTimeoutError`` (errno ETIMEDOUT, code -7)
EndpointHalted / unknown request   ``USBError`` (errno EPIPE, code -9)
DeviceUnplugged                    ``USBError`` (errno ENODEV, code -4)
TransferOverflow                   ``USBError`` (errno EOVERFLOW, code -8)
bad interface / configuration      ``USBError`` (errno ENOENT, code -5)
interface claimed by another handle ``USBError`` (errno EBUSY, code -6)
=================================  ==================================================

Every replug is a new enumeration with a new bus address; a handle opened before stays dead.
"""

from __future__ import annotations

import array
import errno
import logging
import threading
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import usb.backend
import usb.core

from wavestack.simulators.u3v.camera import SimulatedU3VCamera
from wavestack.simulators.u3v.descriptors import (EP_ACK_IN, EP_COMMAND_OUT, EP_STREAM_IN, DeviceUnplugged,
                                                  EndpointDescriptor, EndpointHalted, InterfaceDescriptor,
                                                  TransferError, TransferOverflow, TransferTimeout,
                                                  U3VDescriptorSet, u3v_descriptors)

_log = logging.getLogger(__name__)

_BUS = 1
_LIBUSB = {  # errno -> (libusb error code, libusb message)
    errno.ETIMEDOUT: (-7, "Operation timed out"),
    errno.EPIPE: (-9, "Pipe error"),
    errno.ENODEV: (-4, "No such device (it may have been disconnected)"),
    errno.EOVERFLOW: (-8, "Overflow"),
    errno.ENOENT: (-5, "Entity not found"),
    errno.EBUSY: (-6, "Resource busy"),
    errno.EINVAL: (-2, "Invalid parameter"),
}
_GET_STATUS, _CLEAR_FEATURE, _GET_DESCRIPTOR, _GET_CONFIGURATION = 0x00, 0x01, 0x06, 0x08


def usb_error(code: int, detail: str = "") -> usb.core.USBError:
    """The pyusb exception a libusb backend raises for ``code`` (an errno value)."""
    backend_code, message = _LIBUSB[code]
    text = f"{message}: {detail}" if detail else message
    cls = usb.core.USBTimeoutError if code == errno.ETIMEDOUT else usb.core.USBError
    return cls(text, backend_code, code)


def _translate(error: TransferError) -> usb.core.USBError:
    for kind, code in ((TransferTimeout, errno.ETIMEDOUT), (EndpointHalted, errno.EPIPE),
                       (DeviceUnplugged, errno.ENODEV), (TransferOverflow, errno.EOVERFLOW)):
        if isinstance(error, kind):
            return usb_error(code, str(error))
    return usb_error(errno.EINVAL, str(error))


@dataclass(frozen=True, eq=False)
class SimulatedDeviceId:
    """What ``enumerate_devices`` yields: one camera in one plug session."""

    camera: SimulatedU3VCamera
    session: int
    descriptors: U3VDescriptorSet


@dataclass(eq=False)
class SimulatedHandle:
    """An open device handle (``open_device``)."""

    device: SimulatedDeviceId
    configuration: int = 1
    claimed: set[int] = field(default_factory=set)
    closed: bool = False


class SimulatedUsbBackend(usb.backend.IBackend):
    """pyusb backend over simulated cameras.

    Parameters
    ----------
    cameras
        Cameras on the simulated bus (enumerated in this order while plugged in).
    """

    def __init__(self, cameras: Sequence[SimulatedU3VCamera]) -> None:
        self._cameras = tuple(cameras)
        self._lock = threading.Lock()
        self._addresses: dict[tuple[int, int], int] = {}  # (camera index, session) -> bus address
        self._ids: dict[tuple[int, int], SimulatedDeviceId] = {}
        self._claims: dict[tuple[int, int, int], SimulatedHandle] = {}  # (camera, session, interface) -> owner

    # --- enumeration and descriptors ----------------------------------------------------------
    def enumerate_devices(self) -> Iterator[SimulatedDeviceId]:
        with self._lock:
            found = [self._device_id(i, cam) for i, cam in enumerate(self._cameras) if cam.plugged]
        return iter(found)

    def _device_id(self, index: int, camera: SimulatedU3VCamera) -> SimulatedDeviceId:
        key = (index, camera.session)
        if key not in self._ids:
            address = self._addresses.setdefault(key, 2 + len(self._addresses) % 125)
            s = camera.settings
            descriptors = u3v_descriptors(manufacturer=s.manufacturer, product=s.model, serial=s.serial, bus=_BUS,
                                          address=address, port=index + 1, vendor_id=s.vendor_id,
                                          product_id=s.product_id)
            self._ids[key] = SimulatedDeviceId(camera, camera.session, descriptors)
        return self._ids[key]

    def get_parent(self, dev: SimulatedDeviceId) -> None:
        return None

    def get_device_descriptor(self, dev: SimulatedDeviceId) -> Any:
        return dev.descriptors.device

    def get_configuration_descriptor(self, dev: SimulatedDeviceId, config: int) -> Any:
        if config != 0:
            raise IndexError(f"invalid configuration index {config}")
        return dev.descriptors.configuration

    def get_interface_descriptor(self, dev: SimulatedDeviceId, intf: int, alt: int, config: int) -> Any:
        interfaces = self.get_configuration_descriptor(dev, config).interfaces
        if intf >= len(interfaces):
            raise IndexError(f"invalid interface index {intf}")
        if alt >= len(interfaces[intf]):
            raise IndexError(f"invalid alternate setting index {alt}")
        return interfaces[intf][alt]

    def get_endpoint_descriptor(self, dev: SimulatedDeviceId, ep: int, intf: int, alt: int, config: int) -> Any:
        interface: InterfaceDescriptor = self.get_interface_descriptor(dev, intf, alt, config)
        if ep >= len(interface.endpoints):
            raise IndexError(f"invalid endpoint index {ep}")
        endpoint: EndpointDescriptor = interface.endpoints[ep]
        return endpoint

    # --- handles ------------------------------------------------------------------------------
    def open_device(self, dev: SimulatedDeviceId) -> SimulatedHandle:
        self._require(dev.camera, dev.session)
        return SimulatedHandle(dev)

    def close_device(self, dev_handle: SimulatedHandle) -> None:
        with self._lock:
            for key in [k for k, owner in self._claims.items() if owner is dev_handle]:
                del self._claims[key]
            dev_handle.closed = True

    def set_configuration(self, dev_handle: SimulatedHandle, config_value: int) -> None:
        self._live(dev_handle)
        if config_value not in (0, 1):
            raise usb_error(errno.ENOENT, f"no configuration {config_value}")
        dev_handle.configuration = config_value

    def get_configuration(self, dev_handle: SimulatedHandle) -> int:
        self._live(dev_handle)
        return dev_handle.configuration

    def set_interface_altsetting(self, dev_handle: SimulatedHandle, intf: int, altsetting: int) -> None:
        self._live(dev_handle)
        if intf not in (0, 1) or altsetting != 0:
            raise usb_error(errno.ENOENT, f"no interface {intf} alternate setting {altsetting}")

    def claim_interface(self, dev_handle: SimulatedHandle, intf: int) -> None:
        camera = self._live(dev_handle)
        if intf not in (0, 1):
            raise usb_error(errno.ENOENT, f"no interface {intf}")
        with self._lock:
            key = (self._cameras.index(camera), dev_handle.device.session, intf)
            owner = self._claims.get(key)
            if owner is not None and owner is not dev_handle and not owner.closed:
                raise usb_error(errno.EBUSY, f"interface {intf} is claimed by another handle")
            self._claims[key] = dev_handle
            dev_handle.claimed.add(intf)

    def release_interface(self, dev_handle: SimulatedHandle, intf: int) -> None:
        with self._lock:
            key = (self._cameras.index(dev_handle.device.camera), dev_handle.device.session, intf)
            if self._claims.get(key) is dev_handle:
                del self._claims[key]
            dev_handle.claimed.discard(intf)
        self._live(dev_handle)

    # --- transfers ----------------------------------------------------------------------------
    def bulk_write(self, dev_handle: SimulatedHandle, ep: int, intf: int, data: array.array[int],
                   timeout: int) -> int:
        camera = self._live(dev_handle)
        if ep != EP_COMMAND_OUT:
            raise usb_error(errno.EPIPE, f"endpoint 0x{ep:02x} is not a bulk OUT endpoint")
        try:
            return camera.write_control(data.tobytes(), dev_handle.device.session)
        except TransferError as error:
            raise _translate(error) from None

    def bulk_read(self, dev_handle: SimulatedHandle, ep: int, intf: int, buff: array.array[int],
                  timeout: int) -> int:
        camera = self._live(dev_handle)
        size = len(buff) * buff.itemsize
        session = dev_handle.device.session
        try:
            if ep == EP_ACK_IN:
                data = camera.read_control(size, timeout, session)
            elif ep == EP_STREAM_IN:
                data = camera.read_stream(size, timeout, session)
            else:
                raise usb_error(errno.EPIPE, f"endpoint 0x{ep:02x} is not a bulk IN endpoint")
        except TransferError as error:
            raise _translate(error) from None
        memoryview(buff).cast("B")[:len(data)] = data
        return len(data)

    def clear_halt(self, dev_handle: SimulatedHandle, ep: int) -> None:
        camera = self._live(dev_handle)
        try:
            camera.clear_halt(ep, dev_handle.device.session)
        except TransferError as error:
            raise _translate(error) from None

    def reset_device(self, dev_handle: SimulatedHandle) -> None:
        camera = self._live(dev_handle)
        try:
            camera.reset(dev_handle.device.session)
        except TransferError as error:
            raise _translate(error) from None

    def ctrl_transfer(self, dev_handle: SimulatedHandle, bmRequestType: int, bRequest: int, wValue: int,
                      wIndex: int, data: array.array[int], timeout: int) -> int:
        """Standard requests: GET_DESCRIPTOR (device, configuration, string), GET_STATUS,
        GET_CONFIGURATION and CLEAR_FEATURE(ENDPOINT_HALT); anything else stalls (EPIPE)."""
        self._live(dev_handle)
        descriptors = dev_handle.device.descriptors
        length = len(data) * data.itemsize
        answer: bytes | None = None
        if bmRequestType == 0x80 and bRequest == _GET_DESCRIPTOR:
            kind, index = wValue >> 8, wValue & 0xFF
            if kind == 1:
                answer = descriptors.device.to_bytes()
            elif kind == 2 and index == 0:
                answer = descriptors.configuration.to_bytes()
            elif kind == 3:
                answer = descriptors.string_descriptor(index, wIndex)
        elif bmRequestType in (0x80, 0x81, 0x82) and bRequest == _GET_STATUS:
            answer = bytes(2)
        elif bmRequestType == 0x80 and bRequest == _GET_CONFIGURATION:
            answer = bytes((dev_handle.configuration,))
        elif bmRequestType == 0x02 and bRequest == _CLEAR_FEATURE and wValue == 0:
            self.clear_halt(dev_handle, wIndex & 0xFF)
            return 0
        if answer is None:
            raise usb_error(errno.EPIPE, f"control request 0x{bmRequestType:02x}/0x{bRequest:02x} not supported")
        answer = answer[:length]
        memoryview(data).cast("B")[:len(answer)] = answer
        return len(answer)

    def is_kernel_driver_active(self, dev_handle: SimulatedHandle, intf: int) -> bool:
        self._live(dev_handle)
        return False

    def detach_kernel_driver(self, dev_handle: SimulatedHandle, intf: int) -> None:
        self._live(dev_handle)
        raise usb_error(errno.ENOENT, "no kernel driver is attached")

    def attach_kernel_driver(self, dev_handle: SimulatedHandle, intf: int) -> None:
        self._live(dev_handle)
        raise usb_error(errno.ENOENT, "no kernel driver to attach")

    # --- helpers ------------------------------------------------------------------------------
    @staticmethod
    def _require(camera: SimulatedU3VCamera, session: int) -> SimulatedU3VCamera:
        if not camera.is_present(session):
            raise usb_error(errno.ENODEV, f"camera {camera.settings.serial} is not on the bus")
        return camera

    def _live(self, dev_handle: SimulatedHandle) -> SimulatedU3VCamera:
        if dev_handle.closed:
            raise usb_error(errno.ENODEV, "handle closed")
        return self._require(dev_handle.device.camera, dev_handle.device.session)
