"""Hostile and malformed GenApi XML: every one is one ProtocolError naming the device, and none hangs.

The XML comes from the device, so a broken or malicious camera (or a man in the middle on a GigE
link) controls it: entity expansion, deep nesting, huge files, formulas that divide by zero and
pointers that loop must all end in an error that names the camera.
"""

from __future__ import annotations

import io
import zipfile

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fuzz import fuzz_settings
from wavestack.drivers.errors import DeviceError, ProtocolError
from wavestack.drivers.genicam import NodeMap
from wavestack.drivers.genicam.document import MAX_XML_BYTES
from wavestack.simulators.u3v import genicam_xml
from wavestack.simulators.u3v.device_description import DeviceIdentity

DEVICE = "hostile camera SN 666"
NS = "http://www.genicam.org/GenApi/Version_1_1"
LAUGHS = ('<!DOCTYPE r [<!ENTITY a "lollollollollollollollollollol">'
          + "".join(f'<!ENTITY {chr(98 + i)} "{("&" + chr(97 + i) + ";") * 10}">' for i in range(8)) + "]>")


class Zeros:
    def read(self, address: int, length: int) -> bytes:
        return bytes(length)

    def write(self, address: int, data: bytes) -> None:
        pass


def document(body: str) -> bytes:
    return f'<RegisterDescription xmlns="{NS}">{body}<Port Name="Device"/></RegisterDescription>'.encode()


def zipped(data: bytes) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("camera.xml", data)
    return buffer.getvalue()


@pytest.mark.parametrize(("data", "message"), [
    ((LAUGHS + '<RegisterDescription><Integer Name="&i;"/></RegisterDescription>').encode(), "DTD"),
    (('<?xml version="1.0" encoding="UTF-16"?>' + LAUGHS + "<RegisterDescription/>").encode("utf-16"), "DTD"),
    (b'<!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]><RegisterDescription>&x;</RegisterDescription>',
     "DTD"),
    (b"<RegisterDescription>" + b"<Group>" * 40 + b"</Group>" * 40 + b"</RegisterDescription>", "nests"),
    (b"<RegisterDescription>" + b" " * (MAX_XML_BYTES + 1) + b"</RegisterDescription>", "at most"),
    (zipped(b"<RegisterDescription>" + b" " * (MAX_XML_BYTES + 10) + b"</RegisterDescription>"), "expected <= |inflates"),
    (b"<RegisterDescription", "well-formed"),
    (b'<Other xmlns="http://www.genicam.org/GenApi/Version_1_1"/>', "RegisterDescription"),
    (b'<RegisterDescription xmlns="urn:something-else"/>', "RegisterDescription"),
    (b"PK\x03\x04 broken", "ZIP"),
])
def test_hostile_documents_are_refused_at_load(data: bytes, message: str) -> None:
    with pytest.raises(ProtocolError, match=message) as caught:
        NodeMap.from_xml(data, device=DEVICE)
    assert caught.value.device == DEVICE


@pytest.mark.parametrize(("body", "feature", "message"), [
    ('<Integer Name="Width"><pValue>A</pValue></Integer><Integer Name="A"><pValue>B</pValue></Integer>'
     '<Integer Name="B"><pValue>A</pValue></Integer>', "Width", "pointer loop A -> B -> A"),
    ('<IntSwissKnife Name="Width"><pVariable Name="X">Width</pVariable><Formula>X + 1</Formula></IntSwissKnife>',
     "Width", "pointer loop Width -> Width"),
    ('<Integer Name="Width"><pValue>K</pValue></Integer><IntSwissKnife Name="K"><pVariable Name="Z">Zero</pVariable>'
     '<Formula>100 / Z</Formula></IntSwissKnife><Integer Name="Zero"><Value>0</Value></Integer>', "Width",
     "division by zero"),
    ('<Integer Name="Width"><pValue>R</pValue></Integer><IntReg Name="R"><pAddress>K</pAddress><Length>4</Length>'
     '<AccessMode>RW</AccessMode><pPort>Device</pPort></IntReg><IntSwissKnife Name="K"><Formula>1 % 0</Formula>'
     "</IntSwissKnife>", "Width", "division by zero"),
    ('<IntSwissKnife Name="Width"><Expression Name="X2">X2 + 1</Expression><Formula>X2</Formula></IntSwissKnife>',
     "Width", "refers to itself"),
    ('<Integer Name="Width"><pValue>N0</pValue></Integer>'
     + "".join(f'<Integer Name="N{i}"><pValue>N{i + 1}</pValue></Integer>' for i in range(80))
     + '<Integer Name="N80"><Value>1</Value></Integer>', "Width", "more than 64"),
    ('<Integer Name="Width"><Value>1</Value><Min>nan</Min></Integer>', "Width", "expected an integer"),
    ('<Float Name="Width"><Value>1</Value><Max>inf</Max></Float>', "Width", "finite"),
    ('<Integer Name="Width"><pValue>R</pValue></Integer><IntReg Name="R"><Address>0</Address><Length>99</Length>'
     '<AccessMode>RW</AccessMode><pPort>Device</pPort></IntReg>', "Width", "length"),
    ('<Integer Name="Width"><pValue>R</pValue></Integer><IntReg Name="R"><Address>0</Address><Length>4</Length>'
     '<AccessMode>RW</AccessMode><pPort>Chunk</pPort></IntReg>', "Width", "port 'Chunk' is not attached"),
    ('<Command Name="Width"><pValue>R</pValue><CommandValue>0x100000000</CommandValue></Command>'
     '<IntReg Name="R"><Address>0</Address><Length>4</Length><AccessMode>WO</AccessMode><pPort>Device</pPort>'
     "</IntReg>", "Width", "does not fit"),
])
def test_hostile_nodes_are_one_error_naming_the_device_and_feature(body: str, feature: str, message: str) -> None:
    nodes = NodeMap.from_xml(document(body), device=DEVICE)
    nodes.attach(Zeros())
    with pytest.raises(ProtocolError, match=message) as caught:
        nodes.info(feature)
        if nodes.info(feature).kind == "command":
            nodes.execute(feature)
        else:
            nodes.get(feature)
            nodes.set(feature, 1)
    assert caught.value.device == DEVICE and feature in str(caught.value)


SIM_XML = genicam_xml(DeviceIdentity("wavestack", "Sim", "Sim", "1.0", "fuzz", "SN1", 200, 1024, 1024))


@st.composite
def mutations(draw: st.DrawFn, data: bytes) -> bytes:
    position = draw(st.integers(0, len(data)))
    cut = draw(st.integers(0, 40))
    return data[:position] + draw(st.binary(max_size=20)) + data[position + cut:]


@fuzz_settings(200)
@given(data=st.one_of(mutations(SIM_XML), st.binary(max_size=200), st.text(max_size=200).map(str.encode)))
def test_any_document_loads_and_evaluates_or_raises_device_errors(data: bytes) -> None:
    try:
        nodes = NodeMap.from_xml(data, device=DEVICE)
    except ProtocolError as error:
        assert error.device == DEVICE
        return
    nodes.attach(Zeros())
    for name in ("Width", "Height", "PixelFormat", "ExposureTime", "TriggerMode", "AcquisitionStart"):
        if name in nodes:
            try:
                nodes.info(name)
                nodes.get(name)
            except DeviceError as error:
                assert error.device == DEVICE
