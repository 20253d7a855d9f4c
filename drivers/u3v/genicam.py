"""The few GenICam features wavestack needs, read from a device's GenApi XML, without I/O.

Supported subset (anything else met while resolving a wanted feature raises ``ProtocolError``
naming the feature):

* Root ``RegisterDescription`` in a GenApi namespace (``http://www.genicam.org/GenApi/...``,
  normally ``Version_1_1``) or in no namespace. Nodes are its children or children of ``Group``.
* ``Integer`` with one ``pValue`` -> ``IntReg``; optional constant ``Min``/``Max`` (finite,
  ``Min <= Max``).
* ``Float`` with one ``pValue`` -> ``FloatReg``; optional constant ``Min``/``Max`` (likewise).
* ``Enumeration`` with ``EnumEntry`` children (``Name`` attribute, integer ``Value`` that fits the
  register unsigned) and one ``pValue`` -> ``IntReg``.
* ``Command`` with one ``pValue`` -> ``IntReg`` and a constant ``CommandValue`` that fits the register.
* ``IntReg``: one constant ``Address`` (no ``pAddress``, ``IntSwissKnife`` or ``pIndex``),
  ``Length`` 4 or 8, ``AccessMode`` RO/RW/WO (default RO), ``Endianess`` LittleEndian (default),
  ``Sign`` Unsigned (default).
* ``FloatReg``: as ``IntReg`` without ``Sign``; ``Length`` 4 (float32) or 8 (float64).
* ``StringReg`` as the feature itself (how the SFNC Device Control strings, ``DeviceVendorName`` and
  the like, are described): one constant ``Address``, ``Length`` 1..4096, ``AccessMode``; the value is
  ASCII, NUL-padded.

Features in :data:`OPTIONAL_FEATURES` (the SFNC identity strings, ``AcquisitionMode``,
``PayloadSize``, ``TLParamsLocked``) are read when the device describes them within the subset and
left out otherwise: a camera that builds them from nodes outside the subset still opens.

Presentation elements (``ToolTip``, ``DisplayName``, ``Visibility``, ``pInvalidator``, ...) are
ignored. Integers are decimal or ``0x`` hexadecimal. The XML comes as plain bytes or as a ZIP
holding exactly one ``.xml`` file. Documents with a DTD are refused, in any encoding expat reads
(``xml.etree`` never fetches external entities; refusing DTDs also rules out entity expansion).

Reference: EMVA GenICam Standard, GenApi schema 1.1 (node types IntReg, FloatReg, StringReg,
Integer, Float, Enumeration, Command); GenICam Standard Features Naming Convention (SFNC 2.6) for
the feature names.
"""

from __future__ import annotations

import io
import logging
import math
import xml.etree.ElementTree as ET
import zipfile
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Literal
from xml.parsers import expat

from wavestack.drivers.errors import ProtocolError

logger = logging.getLogger(__name__)

WANTED_FEATURES = ("Width", "Height", "PixelFormat", "ExposureTime", "TriggerMode", "TriggerSoftware",
                   "AcquisitionStart", "AcquisitionStop")
#: SFNC features read when present and within the subset, left out otherwise.
OPTIONAL_FEATURES = ("AcquisitionMode", "PayloadSize", "TLParamsLocked", "DeviceVendorName", "DeviceModelName",
                     "DeviceFamilyName", "DeviceVersion", "DeviceManufacturerInfo", "DeviceSerialNumber",
                     "DeviceUserID")
_MAX_STRING_BYTES = 4096
_GENAPI_NAMESPACE_PREFIX = "http://www.genicam.org/GenApi/"
_MAX_XML_BYTES = 32 << 20  # a GenApi file is kilobytes to a few megabytes; refuse zip bombs
_VALUE_ALTERNATIVES = ("Value", "pValueIndexed", "ValueIndexed", "pValueDefault", "pIndex", "pValueCopy")
_ADDRESS_ALTERNATIVES = ("pAddress", "IntSwissKnife", "pIndex")

FeatureKind = Literal["integer", "float", "enumeration", "command", "string"]
Access = Literal["RO", "RW", "WO"]


@dataclass(frozen=True)
class Register:
    """Where a feature's value lives in the device's register space.

    Attributes
    ----------
    address
        Register address (u64).
    length
        Bytes, 4 or 8 (a string: 1..4096).
    access
        ``"RO"``, ``"RW"`` or ``"WO"``.
    is_float
        IEEE float (``FloatReg``) rather than an unsigned little-endian integer (``IntReg``).
    """

    address: int
    length: int
    access: Access
    is_float: bool = False

    @property
    def readable(self) -> bool:
        return self.access in ("RO", "RW")

    @property
    def writable(self) -> bool:
        return self.access in ("RW", "WO")


@dataclass(frozen=True)
class Feature:
    """One resolved feature.

    Attributes
    ----------
    name
        Feature name, e.g. ``"ExposureTime"``.
    kind
        ``"integer"``, ``"float"``, ``"enumeration"``, ``"command"`` or ``"string"``.
    register
        :class:`Register` holding the value.
    entries
        Enumerations: entry name -> integer value (read-only mapping); empty otherwise.
    command_value
        Commands: the value to write to execute; ``None`` otherwise.
    minimum, maximum
        Constant ``Min``/``Max`` from the XML, or ``None``.
    """

    name: str
    kind: FeatureKind
    register: Register
    entries: Mapping[str, int] = field(default_factory=dict)
    command_value: int | None = None
    minimum: float | None = None
    maximum: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "entries", MappingProxyType(dict(self.entries)))

    def entry_name(self, value: int) -> str | None:
        """The enumeration entry with this value, or ``None``."""
        for name, entry_value in self.entries.items():
            if entry_value == value:
                return name
        return None


@dataclass(frozen=True)
class FeatureMap:
    """The wanted features found in a device's XML (missing ones are simply absent).

    Attributes
    ----------
    features
        Feature name -> :class:`Feature` (read-only mapping).
    """

    features: Mapping[str, Feature]

    def __post_init__(self) -> None:
        object.__setattr__(self, "features", MappingProxyType(dict(self.features)))

    def __contains__(self, name: object) -> bool:
        return name in self.features

    def require(self, name: str, device: str) -> Feature:
        """The feature ``name``.

        Raises
        ------
        ProtocolError
            The device's XML does not describe it.
        """
        try:
            return self.features[name]
        except KeyError:
            raise ProtocolError(device, f"feature {name!r} is not described in the device's GenICam XML; "
                                        f"found {sorted(self.features)}") from None


def extract_xml(data: bytes, device: str, *, zipped: bool | None = None) -> bytes:
    """The XML bytes of a GenICam file that is plain or a ZIP holding one ``.xml``.

    Parameters
    ----------
    data
        File contents as read from the device.
    device
        Device name for error messages.
    zipped
        ``True``/``False`` from the manifest's file format; ``None`` sniffs the ZIP signature.

    Raises
    ------
    ProtocolError
        A broken ZIP, not exactly one ``.xml`` member, or a member larger than 32 MiB.
    """
    data = bytes(data)
    if zipped is None:
        zipped = data[:4] == b"PK\x03\x04"
    if not zipped:
        return data
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            members = [info for info in archive.infolist() if info.filename.lower().endswith(".xml")]
            if len(members) != 1:
                raise ProtocolError(device, f"expected a GenICam ZIP holding exactly one .xml file, "
                                            f"found {[info.filename for info in members]}")
            member = members[0]
            if member.file_size > _MAX_XML_BYTES:
                raise ProtocolError(device, f"GenICam XML {member.filename!r} is {member.file_size} B, "
                                            f"expected <= {_MAX_XML_BYTES} B")
            with archive.open(member) as stream:
                xml = stream.read(_MAX_XML_BYTES + 1)
    except ProtocolError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, NotImplementedError, EOFError, zlib.error, ValueError,
            OSError, KeyError, RuntimeError, OverflowError, IndexError) as exc:
        raise ProtocolError(device, f"expected a readable GenICam ZIP file: {exc}") from None
    if len(xml) > _MAX_XML_BYTES:
        raise ProtocolError(device, f"GenICam XML inflates beyond {_MAX_XML_BYTES} B")
    return xml


class _DtdFound(Exception):
    """Raised from the expat handlers when a document declares a DTD or an entity."""


def _refuse_dtd(xml: bytes, device: str) -> None:
    """Refuse a DTD or entity declaration in any encoding expat decodes (a byte search misses UTF-16);
    this pass stops at the first declaration, before any entity is expanded."""
    parser = expat.ParserCreate()

    def found(*_: object) -> None:
        raise _DtdFound

    parser.StartDoctypeDeclHandler = parser.EntityDeclHandler = found
    try:
        parser.Parse(xml, True)
    except _DtdFound:
        raise ProtocolError(device, "GenICam XML with a DTD or entity declarations is refused") from None
    except (expat.ExpatError, ValueError, LookupError, UnicodeError):
        pass  # not well-formed: the tree parser reports it with its position


def _local(tag: object) -> str:
    text = tag if isinstance(tag, str) else ""
    return text.rsplit("}", 1)[-1]


def _parse_int(text: str | None, what: str, device: str) -> int:
    value = (text or "").strip()
    try:
        if value.lower().startswith(("0x", "-0x")):
            return int(value, 16)
        return int(value, 10)
    except ValueError:
        raise ProtocolError(device, f"{what}: expected an integer, got {value!r}") from None


def _parse_float(text: str | None, what: str, device: str) -> float:
    value = (text or "").strip()
    try:
        return float(value)
    except ValueError:
        raise ProtocolError(device, f"{what}: expected a number, got {value!r}") from None


class _Resolver:
    """Resolves wanted features through an index of named nodes (one parse, no shared state)."""

    def __init__(self, root: ET.Element, device: str) -> None:
        self._device = device
        self._nodes: dict[str, ET.Element] = {}
        self._duplicates: set[str] = set()
        stack = [root]
        while stack:
            parent = stack.pop()
            for child in parent:
                if _local(child.tag) == "Group":
                    stack.append(child)
                    continue
                name = child.get("Name")
                if name is None:
                    continue
                if name in self._nodes:
                    self._duplicates.add(name)
                self._nodes[name] = child

    def has(self, name: str) -> bool:
        return name in self._nodes

    def _fail(self, feature: str, message: str) -> ProtocolError:
        return ProtocolError(self._device, f"GenICam feature {feature!r}: {message}")

    def _node(self, feature: str, name: str) -> ET.Element:
        if name in self._duplicates:
            raise self._fail(feature, f"node {name!r} is defined more than once")
        try:
            return self._nodes[name]
        except KeyError:
            raise self._fail(feature, f"references node {name!r}, which the XML does not define") from None

    def _children(self, feature: str, node: ET.Element, tag: str) -> list[ET.Element]:
        return [child for child in node if _local(child.tag) == tag]

    def _one_text(self, feature: str, node: ET.Element, tag: str, *, default: str | None = None) -> str:
        found = self._children(feature, node, tag)
        if not found:
            if default is not None:
                return default
            raise self._fail(feature, f"{_local(node.tag)} {node.get('Name')!r} lacks <{tag}>")
        if len(found) > 1:
            raise self._fail(feature, f"{_local(node.tag)} {node.get('Name')!r} has {len(found)} <{tag}> "
                                      f"elements; the supported subset allows one")
        return (found[0].text or "").strip()

    def _refuse(self, feature: str, node: ET.Element, tags: tuple[str, ...]) -> None:
        for tag in tags:
            if self._children(feature, node, tag):
                raise self._fail(feature, f"{_local(node.tag)} {node.get('Name')!r} uses <{tag}>, "
                                          f"outside the supported subset")

    def _register(self, feature: str, name: str, *, want_float: bool) -> Register:
        node = self._node(feature, name)
        tag = _local(node.tag)
        expected = "FloatReg" if want_float else "IntReg"
        if tag != expected:
            raise self._fail(feature, f"pValue {name!r} is a {tag}; the supported subset expects {expected}")
        self._refuse(feature, node, _ADDRESS_ALTERNATIVES)
        address = _parse_int(self._one_text(feature, node, "Address"), f"{feature} Address", self._device)
        length = _parse_int(self._one_text(feature, node, "Length"), f"{feature} Length", self._device)
        access = self._one_text(feature, node, "AccessMode", default="RO")
        endianess = self._one_text(feature, node, "Endianess", default="LittleEndian")
        if not 0 <= address <= 0xFFFF_FFFF_FFFF_FFFF:
            raise self._fail(feature, f"address {address} is not a u64")
        if length not in (4, 8):
            raise self._fail(feature, f"register length {length} B; expected 4 or 8")
        if access not in ("RO", "RW", "WO"):
            raise self._fail(feature, f"AccessMode {access!r}; expected RO, RW or WO")
        if endianess != "LittleEndian":
            raise self._fail(feature, f"Endianess {endianess!r}; expected LittleEndian")
        if not want_float:
            sign = self._one_text(feature, node, "Sign", default="Unsigned")
            if sign != "Unsigned":
                raise self._fail(feature, f"Sign {sign!r}; expected Unsigned")
        return Register(address, length, access, want_float)  # type: ignore[arg-type]

    def _limit(self, feature: str, node: ET.Element, tag: str) -> float | None:
        if not self._children(feature, node, tag):
            return None
        value = _parse_float(self._one_text(feature, node, tag), f"{feature} {tag}", self._device)
        if not math.isfinite(value):  # a NaN limit would compare false and let every value through
            raise self._fail(feature, f"{tag} {value!r}; expected a finite number")
        return value

    def _limits(self, feature: str, node: ET.Element) -> tuple[float | None, float | None]:
        low, high = self._limit(feature, node, "Min"), self._limit(feature, node, "Max")
        if low is not None and high is not None and low > high:
            raise self._fail(feature, f"Min {low!r} exceeds Max {high!r}; expected Min <= Max")
        return low, high

    def _register_value(self, feature: str, text: str, what: str, register: Register) -> int:
        """An integer from the XML that is written to ``register``: it must fit its unsigned width."""
        value = _parse_int(text, f"{feature} {what}", self._device)
        if not 0 <= value < 1 << (8 * register.length):
            raise self._fail(feature, f"{what} {value} does not fit the {register.length}-byte unsigned register; "
                                      f"expected 0..{(1 << (8 * register.length)) - 1}")
        return value

    def _string(self, feature: str, node: ET.Element) -> Feature:
        self._refuse(feature, node, _ADDRESS_ALTERNATIVES)
        address = _parse_int(self._one_text(feature, node, "Address"), f"{feature} Address", self._device)
        length = _parse_int(self._one_text(feature, node, "Length"), f"{feature} Length", self._device)
        access = self._one_text(feature, node, "AccessMode", default="RO")
        if not 0 <= address <= 0xFFFF_FFFF_FFFF_FFFF or not 1 <= length <= _MAX_STRING_BYTES:
            raise self._fail(feature, f"StringReg at {address} of {length} B; expected a u64 address, 1..4096 B")
        if access not in ("RO", "RW", "WO"):
            raise self._fail(feature, f"AccessMode {access!r}; expected RO, RW or WO")
        return Feature(feature, "string", Register(address, length, access))  # type: ignore[arg-type]

    def resolve(self, feature: str) -> Feature:
        node = self._node(feature, feature)
        tag = _local(node.tag)
        if tag == "StringReg":
            return self._string(feature, node)
        if tag not in ("Integer", "Float", "Enumeration", "Command"):
            raise self._fail(feature, f"node type {tag!r} is outside the supported subset "
                                      f"(Integer, Float, Enumeration, Command)")
        self._refuse(feature, node, _VALUE_ALTERNATIVES)
        register = self._register(feature, self._one_text(feature, node, "pValue"), want_float=tag == "Float")
        if tag in ("Integer", "Float"):
            kind: FeatureKind = "integer" if tag == "Integer" else "float"
            low, high = self._limits(feature, node)
            return Feature(feature, kind, register, minimum=low, maximum=high)
        if tag == "Command":
            value = self._register_value(feature, self._one_text(feature, node, "CommandValue"), "CommandValue",
                                         register)
            return Feature(feature, "command", register, command_value=value)
        entries: dict[str, int] = {}
        for entry in self._children(feature, node, "EnumEntry"):
            entry_name = entry.get("Name")
            if not entry_name or entry_name in entries:
                raise self._fail(feature, f"EnumEntry name {entry_name!r} is missing or repeated")
            entries[entry_name] = self._register_value(feature, self._one_text(feature, entry, "Value"),
                                                       f"entry {entry_name} Value", register)
        if not entries:
            raise self._fail(feature, "enumeration has no EnumEntry")
        return Feature(feature, "enumeration", register, entries=entries)


def parse_genicam(data: bytes, device: str, *, zipped: bool | None = None,
                  wanted: tuple[str, ...] = WANTED_FEATURES,
                  optional: tuple[str, ...] = OPTIONAL_FEATURES) -> FeatureMap:
    """Parse a GenICam file into the wanted features' registers.

    Parameters
    ----------
    data
        The file as read from the device (plain XML or ZIP).
    device
        Device name for error messages.
    zipped
        From the manifest's file format (``None`` sniffs the ZIP signature).
    wanted
        Feature names to resolve; those the XML does not define are left out of the result.
    optional
        Feature names resolved like ``wanted`` but also left out (logged) when outside the subset.

    Returns
    -------
    FeatureMap

    Raises
    ------
    ProtocolError
        Not well-formed XML, a DTD, a root other than a GenApi ``RegisterDescription``, or a wanted
        feature outside the supported subset (the message names the feature).
    """
    xml = extract_xml(data, device, zipped=zipped)
    _refuse_dtd(xml, device)
    try:
        root = ET.fromstring(xml)
    except (ET.ParseError, ValueError, LookupError, UnicodeError) as exc:
        raise ProtocolError(device, f"expected well-formed GenICam XML: {exc}") from None
    tag = root.tag if isinstance(root.tag, str) else ""
    namespace = tag[1:].split("}", 1)[0] if tag.startswith("{") else ""
    if _local(tag) != "RegisterDescription" or (namespace and not namespace.startswith(_GENAPI_NAMESPACE_PREFIX)):
        raise ProtocolError(device, f"expected a GenApi <RegisterDescription> root, got {tag!r}")
    resolver = _Resolver(root, device)
    features = {name: resolver.resolve(name) for name in wanted if resolver.has(name)}
    for name in optional:
        if resolver.has(name) and name not in features:
            try:
                features[name] = resolver.resolve(name)
            except ProtocolError as error:
                logger.info("%s: optional feature %s left out (%s)", device, name, error)
    return FeatureMap(features)
