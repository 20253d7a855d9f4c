"""What the simulated USB3 Vision camera says about itself: its identity and its feature table.

:class:`DeviceIdentity` is what the bootstrap registers (ABRM, SBRM) report; :data:`FEATURES` are
the GenICam features the XML describes and the feature registers at :data:`FEATURE_BASE_ADDRESS`
serve.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from wavestack.simulators.u3v.register_map import AccessMode

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


PIXEL_FORMAT_ENTRIES: tuple[tuple[str, int], ...] = (("Mono8", 0x0108_0001), ("Mono12", 0x0110_0005),
                                                     ("Mono16", 0x0110_0007))

FEATURES: tuple[FeatureSpec, ...] = (
    FeatureSpec("Width", "Integer", FEATURE_BASE_ADDRESS + 0x00, 4, "RW", 1, 16384),
    FeatureSpec("Height", "Integer", FEATURE_BASE_ADDRESS + 0x04, 4, "RW", 1, 16384),
    FeatureSpec("PixelFormat", "Enumeration", FEATURE_BASE_ADDRESS + 0x08, 4, "RW", entries=PIXEL_FORMAT_ENTRIES),
    FeatureSpec("TriggerMode", "Enumeration", FEATURE_BASE_ADDRESS + 0x0C, 4, "RW", entries=(("Off", 0), ("On", 1))),
    FeatureSpec("ExposureTime", "Float", FEATURE_BASE_ADDRESS + 0x10, 8, "RW", 1.0, 10_000_000.0, unit="us"),
    FeatureSpec("TriggerSoftware", "Command", FEATURE_BASE_ADDRESS + 0x18, 4, "WO"),
    FeatureSpec("AcquisitionStart", "Command", FEATURE_BASE_ADDRESS + 0x1C, 4, "WO"),
    FeatureSpec("AcquisitionStop", "Command", FEATURE_BASE_ADDRESS + 0x20, 4, "WO"),
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
