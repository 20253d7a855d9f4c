"""The GenICam XML of the simulated USB3 Vision camera and the file the manifest serves it as.

:func:`genicam_xml` writes the GenApi schema 1.1 subset of the protocol sheet for a feature table;
:func:`manifest_file` wraps it as plain XML or as a ZIP archive, with its file-format-info word.
"""

from __future__ import annotations

import io
import uuid
import xml.etree.ElementTree as ET
import zipfile

from wavestack.simulators.u3v.device_description import (DEVICE_STRINGS, FEATURES, DeviceIdentity, FeatureSpec,
                                                         StringFeatureSpec)

GENICAM_NAMESPACE = "http://www.genicam.org/GenApi/Version_1_1"
XML_FILE_NAME = "wavestack_sim_u3v.xml"

FILE_TYPE_XML = 0
FILE_TYPE_ZIP = 1

#: The SFNC categories under ``Root``, in the order the XML lists them.
CATEGORIES = ("DeviceControl", "ImageFormatControl", "AcquisitionControl", "TransportLayerControl")


def child(parent: ET.Element, tag: str, text: str | None = None, **attrs: str) -> ET.Element:
    """A new sub-element of ``parent`` with ``text`` and attributes."""
    element = ET.SubElement(parent, tag, attrs)
    element.text = text
    return element


def genicam_xml(identity: DeviceIdentity, features: tuple[FeatureSpec, ...] = FEATURES,
                strings: tuple[StringFeatureSpec, ...] = DEVICE_STRINGS, *, big_endian: bool = False,
                tooltip: str = "wavestack simulated USB3 Vision camera") -> bytes:
    """The device's GenICam XML (GenApi schema 1.1 subset of the protocol sheet), UTF-8 bytes.

    Each feature is an ``Integer``/``Float``/``Enumeration``/``Command`` node whose ``pValue`` names
    an ``IntReg``/``FloatReg`` called ``<Feature>Reg`` (little-endian unless ``big_endian``, as GigE
    Vision registers are; hexadecimal ``Address``); a
    feature another one locks carries ``pIsLocked``, a register other writes change names them in
    ``pInvalidator``. Each string feature is a ``StringReg`` on its
    ABRM string. The SFNC categories (:data:`CATEGORIES`) under ``Root`` list every feature, and a
    ``Port`` node named ``Device`` is included as any GenICam file has it.
    """
    guid = uuid.uuid5(uuid.NAMESPACE_DNS, f"{identity.manufacturer}.{identity.model}.wavestack")
    root = ET.Element("RegisterDescription", {
        "ModelName": identity.model, "VendorName": identity.manufacturer,
        "ToolTip": tooltip, "StandardNameSpace": "None",
        "SchemaMajorVersion": "1", "SchemaMinorVersion": "1", "SchemaSubMinorVersion": "0",
        "MajorVersion": "1", "MinorVersion": "0", "SubMinorVersion": "0",
        "ProductGuid": str(guid), "VersionGuid": str(uuid.uuid5(guid, identity.device_version)),
        "xmlns": GENICAM_NAMESPACE, "xmlns:xsi": "http://www.w3.org/2001/XMLSchema-instance",
        "xsi:schemaLocation": f"{GENICAM_NAMESPACE} http://www.genicam.org/GenApi/GenApiSchema_Version_1_1.xsd",
    })

    members = [(spec.category, spec.name) for spec in (*strings, *features)]
    categories = {"Root": [c for c in CATEGORIES if any(c == category for category, _ in members)]}
    categories.update({c: [name for category, name in members if category == c] for c in categories["Root"]})
    for name, listed in categories.items():
        category = child(root, "Category", Name=name, NameSpace="Standard")
        for member in listed:
            child(category, "pFeature", member)
    for text in strings:
        node = child(root, "StringReg", Name=text.name, NameSpace="Standard")
        child(node, "Address", f"0x{text.address:08X}")
        child(node, "Length", str(text.length))
        child(node, "AccessMode", text.access)
        child(node, "pPort", "Device")
    for spec in features:
        node = child(root, spec.kind, Name=spec.name, NameSpace="Standard")
        if spec.locked_by:
            child(node, "pIsLocked", spec.locked_by)
        if spec.kind == "Enumeration":
            for entry_name, value in spec.entries:
                entry = child(node, "EnumEntry", Name=entry_name, NameSpace="Standard")
                child(entry, "Value", str(value))
                child(entry, "Symbolic", entry_name)
        child(node, "pValue", spec.name + "Reg")
        if spec.minimum is not None:
            child(node, "Min", repr(spec.minimum) if spec.kind == "Float" else str(int(spec.minimum)))
        if spec.maximum is not None:
            child(node, "Max", repr(spec.maximum) if spec.kind == "Float" else str(int(spec.maximum)))
        if spec.kind == "Integer":
            child(node, "Inc", "1")
        if spec.unit:
            child(node, "Unit", spec.unit)
        if spec.kind == "Command":
            child(node, "CommandValue", str(spec.command_value))
        reg = child(root, "FloatReg" if spec.kind == "Float" else "IntReg", Name=spec.name + "Reg")
        child(reg, "Address", f"0x{spec.address:08X}")
        child(reg, "Length", str(spec.length))
        child(reg, "AccessMode", spec.access)
        child(reg, "pPort", "Device")
        for feature in spec.invalidated_by:
            child(reg, "pInvalidator", feature + "Reg")
        if spec.kind != "Float":
            child(reg, "Sign", "Unsigned")
        child(reg, "Endianess", "BigEndian" if big_endian else "LittleEndian")
    child(root, "Port", Name="Device", NameSpace="Standard")
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)


def manifest_file(xml: bytes, zipped: bool) -> tuple[bytes, int]:
    """The file the manifest points at and its file-format-info word.

    Parameters
    ----------
    xml
        The GenICam XML document.
    zipped
        Store it as a ZIP archive holding one ``.xml`` member (deflated, fixed timestamp so the
        bytes are reproducible).

    Returns
    -------
    (file bytes, format info): bits 0..5 file type (0 XML, 1 ZIP), bits 24..31 / 16..23 GenApi
    schema major / minor (1.1), as the protocol sheet lays them out.
    """
    schema = (1 << 24) | (1 << 16)
    if not zipped:
        return xml, schema | FILE_TYPE_XML
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        info = zipfile.ZipInfo(XML_FILE_NAME, date_time=(1980, 1, 1, 0, 0, 0))
        info.compress_type = zipfile.ZIP_DEFLATED
        archive.writestr(info, xml)
    return buffer.getvalue(), schema | FILE_TYPE_ZIP
