"""The node map on small hand-written XML: node types, addresses, bit fields, caching, access modes."""

from __future__ import annotations

import struct

import pytest

from wavestack.drivers.errors import DeviceTimeout, LimitError, ProtocolError
from wavestack.drivers.genicam import NodeMap

NS = "http://www.genicam.org/GenApi/Version_1_1"
DEVICE = "test camera"


class Memory:
    """A register space: bytes, with a log of every access."""

    def __init__(self, size: int = 0x1000) -> None:
        self.data = bytearray(size)
        self.reads: list[tuple[int, int]] = []
        self.writes: list[tuple[int, bytes]] = []

    def read(self, address: int, length: int) -> bytes:
        self.reads.append((address, length))
        return bytes(self.data[address:address + length])

    def write(self, address: int, data: bytes) -> None:
        self.writes.append((address, bytes(data)))
        self.data[address:address + len(data)] = data

    def u32(self, address: int, value: int, order: str = "<") -> None:
        self.data[address:address + 4] = struct.pack(order + "I", value)


def node_map(body: str, memory: Memory | None = None) -> NodeMap:
    xml = f'<?xml version="1.0"?><RegisterDescription xmlns="{NS}">{body}<Port Name="Device"/></RegisterDescription>'
    result = NodeMap.from_xml(xml.encode(), device=DEVICE)
    if memory is not None:
        result.attach(memory)
    return result


def reg(name: str, address: int, *, tag: str = "IntReg", access: str = "RW", endian: str = "LittleEndian",
        length: int = 4, extra: str = "") -> str:
    return (f"<{tag} Name=\"{name}\"><Address>0x{address:X}</Address><Length>{length}</Length>"
            f"<AccessMode>{access}</AccessMode><pPort>Device</pPort>{extra}<Endianess>{endian}</Endianess></{tag}>")


def test_integer_limits_increment_and_enumeration_through_pointers() -> None:
    memory = Memory()
    memory.u32(0x10, 640), memory.u32(0x14, 16), memory.u32(0x18, 2048), memory.u32(0x1C, 8)
    memory.u32(0x20, 0x01080001)
    nodes = node_map(
        '<Integer Name="Width"><pValue>W</pValue><pMin>WMin</pMin><pMax>WMax</pMax><pInc>WInc</pInc></Integer>'
        + reg("W", 0x10) + reg("WMin", 0x14, access="RO") + reg("WMax", 0x18, access="RO") + reg("WInc", 0x1C, access="RO")
        + '<Enumeration Name="PixelFormat"><EnumEntry Name="Mono8"><Value>0x01080001</Value></EnumEntry>'
          '<EnumEntry Name="Mono12"><Value>0x01100005</Value></EnumEntry>'
          '<EnumEntry Name="Mono16"><pIsImplemented>No</pIsImplemented><Value>0x01100007</Value></EnumEntry>'
          '<pValue>PF</pValue></Enumeration><Integer Name="No"><Value>0</Value></Integer>' + reg("PF", 0x20),
        memory)
    info = nodes.info("Width")
    assert (info.kind, info.access, info.minimum, info.maximum, info.increment) == ("integer", "RW", 16, 2048, 8)
    nodes.set("Width", 1024)
    assert nodes.get("Width") == 1024 and memory.data[0x10:0x14] == struct.pack("<I", 1024)
    for bad in (1020, 8, 4096, 2.5, True):
        with pytest.raises(LimitError, match="Width"):
            nodes.set("Width", bad)  # type: ignore[arg-type]
    assert dict(nodes.info("PixelFormat").entries) == {"Mono8": 0x01080001, "Mono12": 0x01100005}
    assert nodes.get("PixelFormat") == "Mono8"
    nodes.set("PixelFormat", "Mono12")
    assert nodes.get("PixelFormat") == "Mono12" and nodes.get_int("PixelFormat") == 0x01100005
    with pytest.raises(LimitError, match="Mono16"):
        nodes.set("PixelFormat", "Mono16")  # not implemented: refused before the wire


def test_big_endian_bit_fields_count_from_the_most_significant_bit() -> None:
    memory = Memory()
    memory.u32(0x40, 0x8000_0000 | (0b101 << 8), ">")
    nodes = node_map(reg("Top", 0x40, tag="MaskedIntReg", endian="BigEndian", extra="<Bit>0</Bit>")
                     + reg("Field", 0x40, tag="MaskedIntReg", endian="BigEndian", extra="<LSB>23</LSB><MSB>21</MSB>")
                     + reg("Low", 0x40, tag="MaskedIntReg", extra="<Bit>0</Bit>"), memory)
    assert nodes.get("Top") == 1 and nodes.get("Field") == 0b101 and nodes.get("Low") == 0
    nodes.set("Field", 0b010)
    assert struct.unpack(">I", memory.data[0x40:0x44])[0] == 0x8000_0000 | (0b010 << 8)  # other bits kept


def test_struct_entries_share_their_register_and_signed_fields_extend() -> None:
    memory = Memory()
    memory.u32(0x104, 0xF0 | 0b01)
    nodes = node_map('<StructReg Comment="inquiry"><Address>0x100</Address>'
                     '<IntSwissKnife Name="Offset"><Formula>1 * 4</Formula></IntSwissKnife><Length>4</Length>'
                     '<AccessMode>RO</AccessMode><pPort>Device</pPort><Endianess>LittleEndian</Endianess>'
                     '<StructEntry Name="Imp"><Bit>0</Bit></StructEntry><StructEntry Name="Avl"><Bit>1</Bit></StructEntry>'
                     '<StructEntry Name="Nibble"><LSB>4</LSB><MSB>7</MSB><Sign>Signed</Sign></StructEntry></StructReg>',
                     memory)
    assert (nodes.get("Imp"), nodes.get("Avl"), nodes.get("Nibble")) == (1, 0, -1)
    assert memory.reads == [(0x104, 4)]  # one read: the entries share the cached register


def test_a_selector_moves_the_address_of_what_it_selects() -> None:
    memory = Memory()
    memory.u32(0x200 + 0x20 * 1 + 4, 1)
    nodes = node_map(
        '<Enumeration Name="TriggerSelector"><EnumEntry Name="AcquisitionStart"><Value>2</Value></EnumEntry>'
        '<EnumEntry Name="FrameStart"><Value>3</Value></EnumEntry><Value>2</Value>'
        '<pSelected>TriggerMode</pSelected></Enumeration>'
        '<IntSwissKnife Name="Index"><pVariable Name="S">TriggerSelector</pVariable>'
        '<Formula>(S = 2) ? 0 : ((S = 3) ? 1 : 0)</Formula></IntSwissKnife>'
        '<IntSwissKnife Name="Addr"><pVariable Name="I">Index</pVariable><Formula>0x200 + 0x20 * I</Formula></IntSwissKnife>'
        '<Integer Name="TriggerMode"><pValue>Mode</pValue></Integer>'
        '<IntReg Name="Mode"><pAddress>Addr</pAddress><Address>4</Address><Length>4</Length><AccessMode>RW</AccessMode>'
        '<pPort>Device</pPort><Cachable>NoCache</Cachable></IntReg>'
        '<Integer Name="Indexed"><pValue>Table</pValue></Integer>'
        '<IntReg Name="Table"><Address>0x300</Address><pIndex Offset="8">TriggerSelector</pIndex><Length>4</Length>'
        '<AccessMode>RO</AccessMode><pPort>Device</pPort></IntReg>', memory)
    assert nodes.get("TriggerMode") == 0 and memory.reads[-1] == (0x204, 4)
    nodes.set("TriggerSelector", "FrameStart")
    assert nodes.get("TriggerMode") == 1 and memory.reads[-1] == (0x224, 4)
    nodes.get("Indexed")
    assert memory.reads[-1] == (0x300 + 3 * 8, 4)


def test_converters_map_values_and_limits_both_ways() -> None:
    memory = Memory()
    memory.u32(0x10, 100), memory.u32(0x14, 1), memory.u32(0x18, 1_500_000), memory.u32(0x1C, 20_000)
    nodes = node_map(
        '<Float Name="ExposureTimeAbs"><pValue>Conv</pValue><Unit>us</Unit></Float>'
        '<Converter Name="Conv"><pVariable Name="P2">Base</pVariable><FormulaTo>FROM*1000/P2</FormulaTo>'
        '<FormulaFrom>TO*P2/1000</FormulaFrom><pValue>Raw</pValue><Slope>Increasing</Slope></Converter>'
        '<Integer Name="Raw"><pValue>RawReg</pValue><pMin>RawMin</pMin><pMax>RawMax</pMax></Integer>'
        + reg("RawReg", 0x10, extra="<Cachable>NoCache</Cachable>") + reg("RawMin", 0x14, access="RO")
        + reg("RawMax", 0x18, access="RO") + reg("Base", 0x1C, access="RO"), memory)
    info = nodes.info("ExposureTimeAbs")
    assert (info.minimum, info.maximum, info.unit) == (20.0, 30e6, "us")
    assert nodes.get("ExposureTimeAbs") == 2000.0
    nodes.set("ExposureTimeAbs", 5000.0)
    assert struct.unpack("<I", memory.data[0x10:0x14])[0] == 250 and nodes.get("ExposureTimeAbs") == 5000.0
    with pytest.raises(LimitError, match="ExposureTimeAbs"):
        nodes.set("ExposureTimeAbs", 10.0)


def test_caching_follows_cachable_and_invalidators() -> None:
    memory = Memory()
    memory.u32(0x10, 5), memory.u32(0x14, 5 * 4)
    nodes = node_map(
        '<Integer Name="Width"><pValue>W</pValue></Integer>' + reg("W", 0x10)
        + '<Integer Name="PayloadSize"><pValue>P</pValue></Integer>'
        + reg("P", 0x14, access="RO", extra="<pInvalidator>W</pInvalidator>")
        + '<Integer Name="Live"><pValue>L</pValue></Integer>' + reg("L", 0x18, access="RO", extra="<Cachable>NoCache</Cachable>"),
        memory)
    for _ in range(3):
        assert nodes.get("PayloadSize") == 20 and nodes.get("Width") == 5
        nodes.get("Live")
    assert memory.reads.count((0x14, 4)) == 1 and memory.reads.count((0x10, 4)) == 1  # cached
    assert memory.reads.count((0x18, 4)) == 3  # NoCache: read every time
    memory.u32(0x14, 8 * 4)  # the device recomputes the payload when the width changes
    nodes.set("Width", 8)
    assert nodes.get("Width") == 8 and memory.reads.count((0x10, 4)) == 1  # WriteThrough: no read back
    assert nodes.get("PayloadSize") == 32  # invalidated by the write to W


def test_access_modes_from_implemented_available_locked_and_imposed() -> None:
    memory = Memory()
    nodes = node_map(
        '<Integer Name="Gain"><pIsImplemented>Imp</pIsImplemented><pValue>G</pValue></Integer>'
        '<Integer Name="Offset"><pIsAvailable>Avl</pIsAvailable><pValue>G</pValue></Integer>'
        '<Integer Name="Width"><pIsLocked>TLParamsLocked</pIsLocked><pValue>G</pValue></Integer>'
        '<Command Name="Go"><ImposedAccessMode>WO</ImposedAccessMode><pValue>G</pValue><CommandValue>1</CommandValue></Command>'
        '<Integer Name="TLParamsLocked"><Value>0</Value><Min>0</Min><Max>1</Max></Integer>'
        '<Integer Name="Imp"><Value>0</Value></Integer><Integer Name="Avl"><Value>0</Value></Integer>' + reg("G", 0x10),
        memory)
    assert [nodes.access(n) for n in ("Gain", "Offset", "Width", "Go")] == ["NI", "NA", "RW", "WO"]
    nodes.set("TLParamsLocked", 1)  # a value the node map keeps itself: nothing goes to the device
    assert nodes.access("Width") == "RO" and memory.writes == []
    with pytest.raises(ProtocolError, match="Width.*not writable"):
        nodes.set("Width", 3)
    with pytest.raises(ProtocolError, match="Gain.*not readable"):
        nodes.get("Gain")
    nodes.execute("Go")
    assert memory.writes == [(0x10, struct.pack("<I", 1))]


def test_port_errors_pass_through_naming_the_feature() -> None:
    class Silent:
        def read(self, address: int, length: int) -> bytes:
            raise DeviceTimeout(DEVICE, f"no answer reading 0x{address:X}")

        def write(self, address: int, data: bytes) -> None:
            raise DeviceTimeout(DEVICE, "no answer")
    nodes = node_map('<Integer Name="Width"><pValue>W</pValue></Integer>' + reg("W", 0x10))
    nodes.attach(Silent())
    with pytest.raises(DeviceTimeout, match="Width.*no answer"):
        nodes.get("Width")


def test_membership_means_every_pointer_resolves() -> None:
    nodes = node_map('<Integer Name="Width"><pValue>W</pValue></Integer>' + reg("W", 0x10)
                     + '<Integer Name="Height"><pValue>Missing</pValue></Integer>'
                     + '<IntSwissKnife Name="Knife"><Formula>X + 1</Formula></IntSwissKnife>'
                     + '<Integer Name="Gain"><pValue>Knife</pValue></Integer>')
    assert "Width" in nodes and "W" in nodes
    assert "Height" not in nodes and "Gain" not in nodes and "Exposure" not in nodes and 3 not in nodes
    with pytest.raises(ProtocolError, match=f"{DEVICE}.*Height.*does not resolve"):
        nodes.get("Height")
