"""What the simulated USB3 Vision camera says about itself: its identity and its feature table.

:class:`DeviceIdentity` is what the bootstrap registers (ABRM, SBRM) report; :data:`FEATURES` are
the GenICam features the XML describes and the feature registers at :data:`FEATURE_BASE_ADDRESS`
serve; :data:`DEVICE_STRINGS` are the identity features, whose registers are the ABRM's strings.

Feature names, node types and categories follow the GenICam Standard Features Naming Convention
(SFNC 2.6): Device Control (``DeviceVendorName``, ``DeviceModelName``, ``DeviceFamilyName``,
``DeviceVersion``, ``DeviceManufacturerInfo``, ``DeviceSerialNumber``, strings, read-only;
``DeviceUserID``, writable), Image Format Control, Acquisition Control (``AcquisitionMode``, an
enumeration with ``Continuous``) and Transport Layer Control (``PayloadSize``, read-only bytes per
image; ``TLParamsLocked``, 0 or 1, set by the host's transport layer before AcquisitionStart and
cleared after AcquisitionStop; while 1, the features that change the payload cannot be written).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from wavestack.simulators.u3v.register_map import AccessMode

ABRM_ADDRESS = 0x0000_0000
FEATURE_BASE_ADDRESS = 0x0001_0000

FeatureKind = Literal["Integer", "Float", "Enumeration", "Command"]


@dataclass(frozen=True)
class FeatureSpec:
    """One GenICam feature and the register behind it.

    Attributes
    ----------
    name
        Standard feature name (SFNC).
    kind
        GenICam node type of the feature.
    address, length
        Register (little-endian; ``Float`` registers hold an IEEE-754 double).
    access
        Register access mode.
    minimum, maximum
        Inclusive value range (Integer, Float).
    entries
        (symbolic name, value) pairs of an Enumeration.
    command_value
        The value a Command's register expects.
    unit
        Display unit (``us`` for ExposureTime).
    category
        The SFNC category the XML lists it in.
    locked_by
        Name of the feature that locks it while non-zero (``pIsLocked``), or None.
    invalidated_by
        Features whose writes change this register's value (its register's ``pInvalidator``).
    """

    name: str
    kind: FeatureKind
    address: int
    length: int
    access: AccessMode
    minimum: float | None = None
    maximum: float | None = None
    entries: tuple[tuple[str, int], ...] = ()
    command_value: int = 1
    unit: str = ""
    category: str = "AcquisitionControl"
    locked_by: str | None = None
    invalidated_by: tuple[str, ...] = ()


PIXEL_FORMAT_ENTRIES: tuple[tuple[str, int], ...] = (("Mono8", 0x0108_0001), ("Mono12", 0x0110_0005),
                                                     ("Mono16", 0x0110_0007))

#: Values of AcquisitionMode: the simulator streams continuously only (SFNC's SingleFrame and
#: MultiFrame are not offered, since it does not implement them).
ACQUISITION_MODE_ENTRIES: tuple[tuple[str, int], ...] = (("Continuous", 0),)

FEATURES: tuple[FeatureSpec, ...] = (
    FeatureSpec("Width", "Integer", FEATURE_BASE_ADDRESS + 0x00, 4, "RW", 1, 16384, category="ImageFormatControl",
                locked_by="TLParamsLocked"),
    FeatureSpec("Height", "Integer", FEATURE_BASE_ADDRESS + 0x04, 4, "RW", 1, 16384, category="ImageFormatControl",
                locked_by="TLParamsLocked"),
    FeatureSpec("PixelFormat", "Enumeration", FEATURE_BASE_ADDRESS + 0x08, 4, "RW", entries=PIXEL_FORMAT_ENTRIES,
                category="ImageFormatControl", locked_by="TLParamsLocked"),
    FeatureSpec("TriggerMode", "Enumeration", FEATURE_BASE_ADDRESS + 0x0C, 4, "RW", entries=(("Off", 0), ("On", 1))),
    FeatureSpec("ExposureTime", "Float", FEATURE_BASE_ADDRESS + 0x10, 8, "RW", 1.0, 10_000_000.0, unit="us"),
    FeatureSpec("TriggerSoftware", "Command", FEATURE_BASE_ADDRESS + 0x18, 4, "WO"),
    FeatureSpec("AcquisitionStart", "Command", FEATURE_BASE_ADDRESS + 0x1C, 4, "WO"),
    FeatureSpec("AcquisitionStop", "Command", FEATURE_BASE_ADDRESS + 0x20, 4, "WO"),
    FeatureSpec("AcquisitionMode", "Enumeration", FEATURE_BASE_ADDRESS + 0x24, 4, "RW",
                entries=ACQUISITION_MODE_ENTRIES),
    FeatureSpec("PayloadSize", "Integer", FEATURE_BASE_ADDRESS + 0x28, 4, "RO", category="TransportLayerControl",
                invalidated_by=("Width", "Height", "PixelFormat")),
    FeatureSpec("TLParamsLocked", "Integer", FEATURE_BASE_ADDRESS + 0x2C, 4, "RW", 0, 1,
                category="TransportLayerControl"),
)


@dataclass(frozen=True)
class StringFeatureSpec:
    """A string feature (``StringReg``) on one of the ABRM's 64-byte strings.

    Attributes
    ----------
    name
        SFNC feature name (``DeviceVendorName``).
    abrm_register
        The ABRM field behind it (``ManufacturerName``).
    address, length, access
        Where the string lives (ASCII, NUL-padded), and its access mode.
    category
        The SFNC category it belongs to.
    """

    name: str
    abrm_register: str
    address: int
    length: int = 64
    access: AccessMode = "RO"
    category: str = "DeviceControl"


#: The Device Control identity features and the ABRM strings behind them (offsets from the sheet).
DEVICE_STRINGS: tuple[StringFeatureSpec, ...] = (
    StringFeatureSpec("DeviceVendorName", "ManufacturerName", ABRM_ADDRESS + 0x0004),
    StringFeatureSpec("DeviceModelName", "ModelName", ABRM_ADDRESS + 0x0044),
    StringFeatureSpec("DeviceFamilyName", "FamilyName", ABRM_ADDRESS + 0x0084),
    StringFeatureSpec("DeviceVersion", "DeviceVersion", ABRM_ADDRESS + 0x00C4),
    StringFeatureSpec("DeviceManufacturerInfo", "ManufacturerInfo", ABRM_ADDRESS + 0x0104),
    StringFeatureSpec("DeviceSerialNumber", "SerialNumber", ABRM_ADDRESS + 0x0144),
    StringFeatureSpec("DeviceUserID", "UserDefinedName", ABRM_ADDRESS + 0x0184, access="RW"),
)


@dataclass(frozen=True)
class DeviceIdentity:
    """What the bootstrap registers report about the device (strings are ASCII, <= 64 bytes)."""

    manufacturer: str
    model: str
    family: str
    device_version: str
    manufacturer_info: str
    serial: str
    max_response_time_ms: int
    max_command_bytes: int
    max_ack_bytes: int
