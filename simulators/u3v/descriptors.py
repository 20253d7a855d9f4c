"""The USB face of the simulated USB3 Vision camera: descriptors, strings and transfer outcomes.

The descriptor objects carry exactly the attribute names pyusb's ``usb.core`` copies from a
backend (``bLength`` ... ``extra_descriptors``), so :class:`~.backend.SimulatedUsbBackend` can hand
them to the real ``usb.core.Device``. The layout follows the wavestack protocol sheet
(``u3v_spec.md``): device class 0xEF/0x02/0x01 (interface association), one configuration with a
control interface (0xEF/0x05/0x00: bulk OUT 0x01, bulk IN 0x81) and a streaming interface
(0xEF/0x05/0x02: bulk IN 0x82). The event interface (protocol 0x01) is not implemented.

The exceptions at the end are how the device side says a transfer failed; the backend maps them to
the pyusb errors a libusb backend raises (``USBTimeoutError``/ETIMEDOUT, ``USBError`` with EPIPE,
ENODEV, EOVERFLOW).
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

U3V_CLASS = 0xEF
U3V_SUBCLASS = 0x05
PROTOCOL_CONTROL = 0x00
PROTOCOL_EVENT = 0x01
PROTOCOL_STREAM = 0x02

EP_COMMAND_OUT = 0x01
EP_ACK_IN = 0x81
EP_STREAM_IN = 0x82

SIM_VENDOR_ID = 0x1209  # pid.codes test vendor
SIM_PRODUCT_ID = 0x0001

LANGID_EN_US = 0x0409
STRING_MANUFACTURER = 1
STRING_PRODUCT = 2
STRING_SERIAL = 3
STRING_CONTROL_INTERFACE = 4
STRING_STREAM_INTERFACE = 5

LIBUSB_SPEED_SUPER = 4  # libusb_speed enum value for 5 Gbit/s
_BULK = 0x02
_SUPERSPEED_BULK_PACKET = 1024

_DEVICE = struct.Struct("<BBHBBBBHHHBBBB")
_CONFIG = struct.Struct("<BBHBBBBB")
_INTERFACE = struct.Struct("<BBBBBBBBB")
_ENDPOINT = struct.Struct("<BBBBHB")


@dataclass(frozen=True)
class EndpointDescriptor:
    """A bulk endpoint with its SuperSpeed companion descriptor in ``extra_descriptors``."""

    bEndpointAddress: int
    bLength: int = 7
    bDescriptorType: int = 5
    bmAttributes: int = _BULK
    wMaxPacketSize: int = _SUPERSPEED_BULK_PACKET
    bInterval: int = 0
    bRefresh: int = 0
    bSynchAddress: int = 0
    extra_descriptors: tuple[int, ...] = (6, 0x30, 15, 0, 0, 0)  # companion: bMaxBurst 15

    def to_bytes(self) -> bytes:
        """Wire form (endpoint descriptor followed by its companion)."""
        head = _ENDPOINT.pack(self.bLength, self.bDescriptorType, self.bEndpointAddress, self.bmAttributes,
                              self.wMaxPacketSize, self.bInterval)
        return head + bytes(self.extra_descriptors)


@dataclass(frozen=True)
class InterfaceDescriptor:
    """One interface (alternate setting 0) and its endpoints."""

    bInterfaceNumber: int
    bInterfaceProtocol: int
    endpoints: tuple[EndpointDescriptor, ...]
    iInterface: int = 0
    bLength: int = 9
    bDescriptorType: int = 4
    bAlternateSetting: int = 0
    bInterfaceClass: int = U3V_CLASS
    bInterfaceSubClass: int = U3V_SUBCLASS
    extra_descriptors: tuple[int, ...] = ()

    @property
    def bNumEndpoints(self) -> int:
        """Number of endpoints (pyusb reads it as an attribute)."""
        return len(self.endpoints)

    def to_bytes(self) -> bytes:
        """Wire form (interface descriptor followed by its endpoints)."""
        head = _INTERFACE.pack(self.bLength, self.bDescriptorType, self.bInterfaceNumber, self.bAlternateSetting,
                               self.bNumEndpoints, self.bInterfaceClass, self.bInterfaceSubClass,
                               self.bInterfaceProtocol, self.iInterface)
        return head + bytes(self.extra_descriptors) + b"".join(e.to_bytes() for e in self.endpoints)


@dataclass(frozen=True)
class ConfigurationDescriptor:
    """The single configuration; ``interfaces[i]`` lists the alternate settings of interface i."""

    interfaces: tuple[tuple[InterfaceDescriptor, ...], ...]
    bLength: int = 9
    bDescriptorType: int = 2
    bConfigurationValue: int = 1
    iConfiguration: int = 0
    bmAttributes: int = 0x80  # bus powered
    bMaxPower: int = 112  # x 8 mA at SuperSpeed = 896 mA
    # interface association descriptor: interfaces 0..1 form one U3V function
    extra_descriptors: tuple[int, ...] = (8, 0x0B, 0, 2, U3V_CLASS, U3V_SUBCLASS, 0, 0)

    @property
    def bNumInterfaces(self) -> int:
        """Number of interfaces (pyusb reads it as an attribute)."""
        return len(self.interfaces)

    @property
    def wTotalLength(self) -> int:
        """Length of the whole configuration in bytes."""
        return len(self.to_bytes())

    def to_bytes(self) -> bytes:
        """Wire form as GET_DESCRIPTOR(CONFIGURATION) returns it."""
        body = bytes(self.extra_descriptors) + b"".join(alt.to_bytes() for alts in self.interfaces for alt in alts)
        total = _CONFIG.size + len(body)
        head = _CONFIG.pack(self.bLength, self.bDescriptorType, total, self.bNumInterfaces, self.bConfigurationValue,
                            self.iConfiguration, self.bmAttributes, self.bMaxPower)
        return head + body


@dataclass(frozen=True)
class DeviceDescriptor:
    """Device descriptor plus the bus facts libusb adds (bus, address, ports, speed)."""

    idVendor: int
    idProduct: int
    bus: int
    address: int
    bLength: int = 18
    bDescriptorType: int = 1
    bcdUSB: int = 0x0300
    bDeviceClass: int = U3V_CLASS
    bDeviceSubClass: int = 0x02
    bDeviceProtocol: int = 0x01
    bMaxPacketSize0: int = 9  # 2**9 = 512 bytes at SuperSpeed
    bcdDevice: int = 0x0100
    iManufacturer: int = STRING_MANUFACTURER
    iProduct: int = STRING_PRODUCT
    iSerialNumber: int = STRING_SERIAL
    bNumConfigurations: int = 1
    port_number: int = 1
    port_numbers: tuple[int, ...] = (1,)
    speed: int = LIBUSB_SPEED_SUPER

    def to_bytes(self) -> bytes:
        """Wire form as GET_DESCRIPTOR(DEVICE) returns it."""
        return _DEVICE.pack(self.bLength, self.bDescriptorType, self.bcdUSB, self.bDeviceClass,
                            self.bDeviceSubClass, self.bDeviceProtocol, self.bMaxPacketSize0, self.idVendor,
                            self.idProduct, self.bcdDevice, self.iManufacturer, self.iProduct,
                            self.iSerialNumber, self.bNumConfigurations)


@dataclass(frozen=True)
class U3VDescriptorSet:
    """Everything a host learns at enumeration: descriptors and the string table."""

    device: DeviceDescriptor
    configuration: ConfigurationDescriptor
    strings: Mapping[int, str]

    def string_descriptor(self, index: int, langid: int) -> bytes | None:
        """GET_DESCRIPTOR(STRING) answer, or None (the device stalls) for an unknown index or language.

        Parameters
        ----------
        index
            String index; 0 asks for the list of language ids.
        langid
            Language id of the request (ignored for index 0).
        """
        if index == 0:
            return struct.pack("<BBH", 4, 3, LANGID_EN_US)
        if langid != LANGID_EN_US or index not in self.strings:
            return None
        text = self.strings[index].encode("utf-16-le")[:252]
        return bytes((2 + len(text), 3)) + text


def u3v_descriptors(*, manufacturer: str, product: str, serial: str, bus: int, address: int, port: int = 1,
                    vendor_id: int = SIM_VENDOR_ID, product_id: int = SIM_PRODUCT_ID) -> U3VDescriptorSet:
    """Descriptors of a U3V camera as the protocol sheet lays them out.

    Parameters
    ----------
    manufacturer, product, serial
        String descriptors 1, 2 and 3.
    bus, address, port
        Where the host enumerated the device (a replug keeps the port but gets a new address).
    vendor_id, product_id
        USB ids; the defaults are the pid.codes test ids the sheet names.
    """
    control = InterfaceDescriptor(0, PROTOCOL_CONTROL,
                                  (EndpointDescriptor(EP_COMMAND_OUT), EndpointDescriptor(EP_ACK_IN)),
                                  iInterface=STRING_CONTROL_INTERFACE)
    stream = InterfaceDescriptor(1, PROTOCOL_STREAM, (EndpointDescriptor(EP_STREAM_IN),),
                                 iInterface=STRING_STREAM_INTERFACE)
    strings = {STRING_MANUFACTURER: manufacturer, STRING_PRODUCT: product, STRING_SERIAL: serial,
               STRING_CONTROL_INTERFACE: "U3V control", STRING_STREAM_INTERFACE: "U3V stream"}
    return U3VDescriptorSet(
        device=DeviceDescriptor(idVendor=vendor_id, idProduct=product_id, bus=bus, address=address,
                                port_numbers=(port,), port_number=port),
        configuration=ConfigurationDescriptor(((control,), (stream,))),
        strings=MappingProxyType(strings),
    )


class TransferError(Exception):
    """Base of the ways a transfer to the simulated device can fail (mapped to pyusb errors)."""


class TransferTimeout(TransferError):
    """Nothing to read (or the device did not accept data) within the transfer's timeout."""


class EndpointHalted(TransferError):
    """The endpoint is stalled until the host clears the halt."""


class DeviceUnplugged(TransferError):
    """The device is gone (unplugged, or this handle belongs to an earlier plug-in)."""


class TransferOverflow(TransferError):
    """The device sent more bytes than the host's buffer holds; the transfer's data is lost."""
