"""The simulated USB3 Vision camera, exercised only through the real pyusb API.

Every packet here is built by hand with ``struct`` from the protocol sheet (``u3v_spec.md``); the
test neither imports the driver nor the simulator's own encoders, so it checks the simulator
against the sheet rather than against itself.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import io
import struct
import threading
import time
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
import usb.core
import usb.util
from hypothesis import given, settings
from hypothesis import strategies as st

from wavestack.simulators.u3v import SimulatedU3VCamera, SimulatedUsbBackend, U3VSimSettings

# --- constants from the protocol sheet ---------------------------------------------------------
PREFIX = 0x43563355
READMEM, READMEM_ACK, WRITEMEM, WRITEMEM_ACK, PENDING = 0x0800, 0x0801, 0x0802, 0x0803, 0x0805
SUCCESS, NOT_IMPLEMENTED, INVALID_PARAMETER, INVALID_ADDRESS = 0x0000, 0x8001, 0x8002, 0x8003
WRITE_PROTECT, BAD_ALIGNMENT, ACCESS_DENIED, INVALID_HEADER = 0x8004, 0x8005, 0x8006, 0x800E
LEADER_MAGIC, TRAILER_MAGIC = 0x4C563355, 0x54563355
MONO8, MONO12, MONO16 = 0x01080001, 0x01100005, 0x01100007
NS = "{http://www.genicam.org/GenApi/Version_1_1}"
LEADER = struct.Struct("<IHHQHHQIIIIIHH")
TRAILER = struct.Struct("<IHHQHHQI")
ACK = struct.Struct("<IHHHH")
SBRM_MAX_CMD, SBRM_MAX_ACK, SBRM_SIRM_ADDRESS = 0x14, 0x18, 0x20
SI_INFO, SI_CONTROL, SI_REQ_PAYLOAD, SI_REQ_LEADER, SI_REQ_TRAILER = 0x00, 0x04, 0x08, 0x10, 0x14
SI_MAX_LEADER, SI_SIZE, SI_COUNT, SI_FINAL1, SI_FINAL2, SI_MAX_TRAILER = 0x18, 0x1C, 0x20, 0x24, 0x28, 0x2C
STATUS_PAYLOAD_NOT_ALIGNED, STATUS_SI_INCONSISTENT, STATUS_DATA_DISCARDED = 0xA003, 0xA004, 0xA100
TIMEOUT_MS = 2000  # generous: a read that should succeed never waits anywhere near this


class PatternRenderer:
    """Deterministic pixels: value = (7 * block_id + x + 3 * y) * scale, as uint16."""

    def __init__(self, width: int, height: int, scale: int = 1) -> None:
        self.width, self.height, self.scale = width, height, scale
        self.calls: list[int] = []

    def expected(self, block_id: int) -> np.ndarray:
        y, x = np.mgrid[0:self.height, 0:self.width]
        return ((7 * block_id + x + 3 * y) * self.scale).astype(np.uint16)

    def __call__(self, block_id: int, device_time_ns: int, exposure_us: float) -> tuple[np.ndarray, Any]:
        self.calls.append(block_id)
        return self.expected(block_id), {"block_id": block_id, "t_ns": device_time_ns, "exposure_us": exposure_us}


@dataclass(frozen=True)
class Ack:
    status: int
    command_id: int
    request_id: int
    scd: bytes


def command(command_id: int, request_id: int, scd: bytes, flags: int = 0x4000) -> bytes:
    return struct.pack("<IHHHH", PREFIX, flags, command_id, len(scd), request_id) + scd


def parse_ack(raw: bytes) -> Ack:
    prefix, status, command_id, length, request_id = ACK.unpack_from(raw)
    assert prefix == PREFIX
    assert length == len(raw) - ACK.size
    return Ack(status, command_id, request_id, bytes(raw[ACK.size:]))


class Host:
    """A minimal test-side GenCP host over a real ``usb.core.Device``."""

    def __init__(self, dev: usb.core.Device) -> None:
        self.dev = dev
        self.request_id = 0
        self.max_ack = 64  # until the SBRM is read

    def transact(self, command_id: int, scd: bytes) -> Ack:
        self.request_id = self.request_id % 0xFFFF + 1
        self.dev.write(0x01, command(command_id, self.request_id, scd), TIMEOUT_MS)
        ack = parse_ack(bytes(self.dev.read(0x81, 4096, TIMEOUT_MS)))
        assert ack.request_id == self.request_id
        assert ack.command_id == command_id + 1
        return ack

    def readmem(self, address: int, length: int) -> Ack:
        return self.transact(READMEM, struct.pack("<QHH", address, 0, length))

    def writemem(self, address: int, data: bytes) -> Ack:
        return self.transact(WRITEMEM, struct.pack("<Q", address) + data)

    def read(self, address: int, length: int) -> bytes:
        out = b""
        while len(out) < length:
            chunk = min(length - len(out), self.max_ack - ACK.size)
            ack = self.readmem(address + len(out), chunk)
            assert ack.status == SUCCESS, hex(ack.status)
            assert len(ack.scd) == chunk
            out += ack.scd
        return out

    def u32(self, address: int) -> int:
        return struct.unpack("<I", self.read(address, 4))[0]

    def u64(self, address: int) -> int:
        return struct.unpack("<Q", self.read(address, 8))[0]

    def write_u32(self, address: int, value: int) -> int:
        ack = self.writemem(address, struct.pack("<I", value))
        assert struct.unpack("<HH", ack.scd)[1] == (4 if ack.status == SUCCESS else 0)
        return ack.status


def is_u3v(dev: usb.core.Device) -> bool:
    """Match by the sheet's interface classes only (any vendor/product id)."""
    for cfg in dev:
        protocols = {(i.bInterfaceClass, i.bInterfaceSubClass, i.bInterfaceProtocol) for i in cfg}
        if {(0xEF, 0x05, 0x00), (0xEF, 0x05, 0x02)} <= protocols:
            return True
    return False


@contextlib.contextmanager
def plugged(settings_: U3VSimSettings, render: Any) -> Iterator[tuple[SimulatedU3VCamera, Host]]:
    camera = SimulatedU3VCamera(settings_, render)
    dev = usb.core.find(backend=SimulatedUsbBackend([camera]), custom_match=is_u3v)
    assert dev is not None
    try:
        host = Host(dev)
        sbrm = host.u64(0x01D8)
        host.max_ack = host.u32(sbrm + SBRM_MAX_ACK)
        yield camera, host
    finally:
        usb.util.dispose_resources(dev)


def genicam_file(host: Host) -> tuple[bytes, int]:
    """(file bytes, format info) of the first manifest entry; checks its SHA-1."""
    table = host.u64(0x01D0)
    assert host.u64(table) >= 1
    entry = host.read(table + 8, 64)
    version, fmt, address, size = struct.unpack_from("<IIQQ", entry)
    assert version >> 24 == 1
    data = host.read(address, size)
    assert hashlib.sha1(data).digest() == entry[24:44]
    return data, fmt


def feature_nodes(host: Host) -> tuple[ET.Element, dict[str, tuple[int, int, str]]]:
    """Parse the XML; per feature name the (address, length, access) of its register."""
    data, fmt = genicam_file(host)
    if fmt & 0x3F == 1:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            (name,) = archive.namelist()
            assert name.endswith(".xml")
            data = archive.read(name)
    root = ET.fromstring(data)
    assert root.tag == NS + "RegisterDescription"
    registers = {r.get("Name"): r for r in root if r.tag in (NS + "IntReg", NS + "FloatReg")}
    features = {}
    for node in root:
        if node.tag in (NS + "Integer", NS + "Float", NS + "Enumeration", NS + "Command"):
            reg = registers[node.findtext(NS + "pValue")]
            features[node.get("Name")] = (int(reg.findtext(NS + "Address"), 0), int(reg.findtext(NS + "Length")),
                                          reg.findtext(NS + "AccessMode"))
    return root, features


def start_stream(host: Host, size: int, count: int, final1: int, final2: int) -> dict[str, tuple[int, int, str]]:
    _, features = feature_nodes(host)
    sirm = host.u64(host.u64(0x01D8) + SBRM_SIRM_ADDRESS)
    for offset, value in ((SI_MAX_LEADER, 64), (SI_SIZE, size), (SI_COUNT, count), (SI_FINAL1, final1),
                          (SI_FINAL2, final2), (SI_MAX_TRAILER, 64)):
        assert host.write_u32(sirm + offset, value) == SUCCESS
    assert host.write_u32(sirm + SI_CONTROL, 1) == SUCCESS
    assert host.write_u32(features["AcquisitionStart"][0], 1) == SUCCESS
    return features


@dataclass(frozen=True)
class Block:
    leader: tuple[int, ...]
    payload: bytes
    transfer_lengths: tuple[int, ...]
    trailer: tuple[int, ...]


def read_block(host: Host, slots: list[int]) -> Block:
    leader = LEADER.unpack(bytes(host.dev.read(0x82, 64, TIMEOUT_MS)))
    chunks = [bytes(host.dev.read(0x82, slot, TIMEOUT_MS)) for slot in slots]
    trailer = TRAILER.unpack(bytes(host.dev.read(0x82, 64, TIMEOUT_MS)))
    return Block(leader, b"".join(chunks), tuple(len(c) for c in chunks), trailer)


def small_settings(**changes: Any) -> U3VSimSettings:
    base = {"serial": "SIM-A", "width": 6, "height": 5, "pixel_format": "Mono12", "frame_rate_hz": 500.0}
    base.update(changes)
    return U3VSimSettings(**base)


# --- enumeration and descriptors ---------------------------------------------------------------
def test_enumeration_by_class_and_serial() -> None:
    cams = [SimulatedU3VCamera(small_settings(serial=s), PatternRenderer(6, 5)) for s in ("SIM-A", "SIM-B")]
    backend = SimulatedUsbBackend(cams)
    found = list(usb.core.find(find_all=True, backend=backend, custom_match=is_u3v))
    assert [d.serial_number for d in found] == ["SIM-A", "SIM-B"]
    for dev in found:
        assert (dev.bDeviceClass, dev.bDeviceSubClass, dev.bDeviceProtocol) == (0xEF, 0x02, 0x01)
        assert (dev.idVendor, dev.idProduct) == (0x1209, 0x0001)
        cfg = dev.get_active_configuration()
        control = usb.util.find_descriptor(cfg, bInterfaceProtocol=0x00)
        stream = usb.util.find_descriptor(cfg, bInterfaceProtocol=0x02)
        assert sorted(e.bEndpointAddress for e in control) == [0x01, 0x81]
        assert [e.bEndpointAddress for e in stream] == [0x82]
        assert all(usb.util.endpoint_type(e.bmAttributes) == usb.util.ENDPOINT_TYPE_BULK for e in (*control, *stream))
        assert list(cfg.extra_descriptors)[:2] == [8, 0x0B]  # interface association descriptor
        usb.util.dispose_resources(dev)
    by_serial = usb.core.find(backend=backend, custom_match=lambda d: is_u3v(d) and d.serial_number == "SIM-B")
    assert by_serial is not None and by_serial.serial_number == "SIM-B"
    usb.util.dispose_resources(by_serial)


def test_string_descriptors() -> None:
    with plugged(small_settings(serial="XYZ-42", model="ModelQ"), PatternRenderer(6, 5)) as (_, host):
        dev = host.dev
        assert dev.langids == (0x0409,)
        assert (dev.serial_number, dev.product, dev.manufacturer) == ("XYZ-42", "ModelQ", "wavestack")
        assert usb.util.get_string(dev, dev.iSerialNumber) == "XYZ-42"
        with pytest.raises(usb.core.USBError) as stalled:  # unknown string index: the device stalls
            usb.util.get_string(dev, 77)
        assert stalled.value.errno == errno.EPIPE


# --- GenCP and registers -----------------------------------------------------------------------
def test_abrm_sbrm_sirm_fields() -> None:
    cfg = small_settings(serial="S123", model="M9", max_response_time_ms=123, max_transfer_bytes=512,
                         payload_alignment_log2=3, width=10, height=7, pixel_format="Mono16")
    with plugged(cfg, PatternRenderer(10, 7)) as (_, host):
        abrm = host.read(0, 0x204)  # whole ABRM in one go (fits the 512-byte acknowledge)
        assert struct.unpack_from("<HH", abrm, 0) == (0, 1)  # minor, major: GenCP 1.0
        text = lambda off: abrm[off:off + 64].split(b"\0")[0].decode()  # noqa: E731
        assert (text(0x04), text(0x44), text(0x144)) == ("wavestack", "M9", "S123")
        assert struct.unpack_from("<I", abrm, 0x1CC)[0] == 123
        assert struct.unpack_from("<Q", abrm, 0x1FC)[0] == 1  # 1 ns per tick
        sbrm = struct.unpack_from("<Q", abrm, 0x1D8)[0]
        assert host.u32(sbrm + SBRM_MAX_CMD) == 512 and host.u32(sbrm + SBRM_MAX_ACK) == 512
        assert host.u32(sbrm + 0x1C) == 1  # one stream channel
        sirm = host.u64(sbrm + SBRM_SIRM_ADDRESS)
        assert host.u32(sbrm + 0x28) >= 0x30
        assert host.u32(sirm + SI_INFO) >> 24 == 3
        assert host.u64(sirm + SI_REQ_PAYLOAD) == 10 * 7 * 2
        assert (host.u32(sirm + SI_REQ_LEADER), host.u32(sirm + SI_REQ_TRAILER)) == (52, 32)
        assert host.u32(sirm + SI_CONTROL) == 0
        assert host.write_u32(0x1F8, 1) == SUCCESS  # latch the timestamp twice: it never goes back
        first = host.u64(0x1F0)
        assert host.write_u32(0x1F8, 1) == SUCCESS
        assert host.u64(0x1F0) >= first > 0


@pytest.mark.parametrize("zipped", [False, True])
def test_manifest_and_xml_describe_working_registers(zipped: bool) -> None:
    with plugged(small_settings(zipped_xml=zipped, width=9, height=4), PatternRenderer(9, 4)) as (_, host):
        _, fmt = genicam_file(host)
        assert fmt & 0x3F == (1 if zipped else 0)
        assert (fmt >> 24, (fmt >> 16) & 0xFF) == (1, 1)
        root, features = feature_nodes(host)
        assert set(features) == {"Width", "Height", "PixelFormat", "ExposureTime", "TriggerMode",
                                 "TriggerSoftware", "AcquisitionStart", "AcquisitionStop", "AcquisitionMode",
                                 "PayloadSize", "TLParamsLocked"}
        pixel_format = root.find(f"{NS}Enumeration[@Name='PixelFormat']")
        entries = {e.get("Name"): int(e.findtext(NS + "Value"), 0) for e in pixel_format.iter(NS + "EnumEntry")}
        assert entries == {"Mono8": MONO8, "Mono12": MONO12, "Mono16": MONO16}
        assert root.find(f"{NS}Command[@Name='TriggerSoftware']").findtext(NS + "CommandValue") == "1"
        assert features["ExposureTime"][1] in (4, 8) and features["TriggerSoftware"][2] == "WO"
        assert host.u32(features["Width"][0]) == 9 and host.u32(features["Height"][0]) == 4
        assert host.u32(features["PixelFormat"][0]) == MONO12


def test_readmem_writemem_round_trips_and_statuses() -> None:
    with plugged(small_settings(exposure_us=500.0), PatternRenderer(6, 5)) as (_, host):
        _, f = feature_nodes(host)
        exposure = f["ExposureTime"][0]
        assert struct.unpack("<d", host.read(exposure, 8))[0] == 500.0
        ack = host.writemem(exposure, struct.pack("<d", 1234.5))
        assert (ack.status, struct.unpack("<HH", ack.scd)) == (SUCCESS, (0, 8))
        assert struct.unpack("<d", host.read(exposure, 8))[0] == 1234.5
        assert host.write_u32(f["Width"][0], 8) == SUCCESS and host.u32(f["Width"][0]) == 8
        # one command may cover several adjacent registers
        assert host.read(f["Width"][0], 8) == struct.pack("<II", 8, 5)
        assert host.writemem(0x0144, b"EVIL").status == WRITE_PROTECT  # serial number is read-only
        assert host.readmem(0x0FFF_0000, 4).status == INVALID_ADDRESS
        assert host.writemem(0x0FFF_0000, bytes(4)).status == INVALID_ADDRESS
        assert host.writemem(exposure, bytes(4)).status == BAD_ALIGNMENT  # half of an 8-byte register
        assert host.readmem(f["AcquisitionStart"][0], 4).status == ACCESS_DENIED  # write-only
        assert host.write_u32(f["PixelFormat"][0], 0x12345678) == INVALID_PARAMETER
        assert host.write_u32(f["AcquisitionStart"][0], 2) == INVALID_PARAMETER  # not the CommandValue
        assert host.writemem(exposure, struct.pack("<d", float("nan"))).status == INVALID_PARAMETER
        assert host.readmem(0, host.max_ack).status == INVALID_PARAMETER  # ack would exceed the SBRM maximum
        assert host.transact(0x0900, b"").status == NOT_IMPLEMENTED
        # a failed read carries no data
        assert host.readmem(0x0FFF_0000, 4).scd == b""


def test_malformed_headers_and_no_ack_flag() -> None:
    with plugged(small_settings(), PatternRenderer(6, 5)) as (_, host):
        dev = host.dev
        bad_length = struct.pack("<IHHHH", PREFIX, 0x4000, READMEM, 99, 7) + struct.pack("<QHH", 0, 0, 4)
        dev.write(0x01, bad_length, TIMEOUT_MS)
        ack = parse_ack(bytes(dev.read(0x81, 64, TIMEOUT_MS)))
        assert (ack.status, ack.request_id, ack.scd) == (INVALID_HEADER, 7, b"")
        dev.write(0x01, struct.pack("<I", 0x11223344) + bytes(16), TIMEOUT_MS)  # wrong prefix: no ack
        with pytest.raises(usb.core.USBTimeoutError) as timed_out:
            dev.read(0x81, 64, 20)
        assert timed_out.value.errno == errno.ETIMEDOUT
        _, f = feature_nodes(host)
        silent = command(WRITEMEM, 9, struct.pack("<QI", f["Width"][0], 4), flags=0)  # executed, unacknowledged
        dev.write(0x01, silent, TIMEOUT_MS)
        assert host.u32(f["Width"][0]) == 4  # the next ack is this read's, not one for the silent write
        dev.write(0x01, command(READMEM, 3, struct.pack("<QHH", 0, 0, 64)), TIMEOUT_MS)
        with pytest.raises(usb.core.USBError) as overflow:  # 76-byte ack into a 16-byte buffer
            dev.read(0x81, 16, TIMEOUT_MS)
        assert overflow.value.errno == errno.EOVERFLOW


def test_pending_ack_precedes_the_real_ack() -> None:
    with plugged(small_settings(), PatternRenderer(6, 5)) as (camera, host):
        camera.faults.pending_ack_ms = 60
        host.dev.write(0x01, command(READMEM, 42, struct.pack("<QHH", 0, 0, 4)), TIMEOUT_MS)
        pending = parse_ack(bytes(host.dev.read(0x81, 64, TIMEOUT_MS)))
        assert (pending.status, pending.command_id, pending.request_id) == (SUCCESS, PENDING, 42)
        assert struct.unpack("<HH", pending.scd) == (0, 60)
        real = parse_ack(bytes(host.dev.read(0x81, 64, TIMEOUT_MS)))
        assert (real.status, real.command_id, real.request_id, real.scd) == (SUCCESS, READMEM_ACK, 42,
                                                                            struct.pack("<HH", 0, 1))
        camera.faults.pending_ack_ms = 0
        assert host.u32(0) == 0x0001_0000  # back to immediate acknowledges


# --- streaming -------------------------------------------------------------------------------
@pytest.mark.parametrize(("name", "code", "scale", "limit", "dtype"), [
    ("Mono8", MONO8, 20, 255, "u1"), ("Mono12", MONO12, 300, 4095, "<u2"), ("Mono16", MONO16, 2000, 65535, "<u2")])
def test_streamed_block_follows_sirm_sizes(name: str, code: int, scale: int, limit: int, dtype: str) -> None:
    width, height = 6, 5
    render = PatternRenderer(width, height, scale)  # scale pushes the top values past the format's range
    cfg = small_settings(pixel_format=name, payload_alignment_log2=3)
    with plugged(cfg, render) as (camera, host):
        payload = width * height * np.dtype(dtype).itemsize
        # the host's split for alignment 8: count x 16, final1 = remainder floored to 8, final2 = the rest rounded up
        count, remainder = divmod(payload, 16)
        final1 = remainder // 8 * 8
        final2 = -(-(remainder - final1) // 8) * 8
        start_stream(host, 16, count, final1, final2)
        slots = [16] * count + [s for s in (final1, final2) if s]
        block = read_block(host, slots)
        magic, _, leader_size, block_id, _, payload_type, timestamp, fmt, sx, sy, ox, oy, pad, _ = block.leader
        assert (magic, leader_size, payload_type, fmt, sx, sy, ox, oy, pad) == (
            LEADER_MAGIC, 52, 1, code, width, height, 0, 0, 0)
        rendered = render.expected(block_id)
        if limit < 65535:  # pattern maximum (7 id + 17) * scale lies past the range: saturation is exercised
            assert rendered.max() > limit
        expected = np.minimum(rendered, limit).astype(dtype)  # saturated, little-endian
        assert block.payload == expected.tobytes()
        assert sum(block.transfer_lengths) == payload
        t_magic, _, t_size, t_block, status, _, valid, size_y = block.trailer
        assert (t_magic, t_size, t_block, status, valid, size_y) == (TRAILER_MAGIC, 32, block_id, 0, payload, height)
        truth = camera.truth(block_id)
        assert truth["block_id"] == block_id and truth["t_ns"] == timestamp


def test_sirm_checks_alignment_and_consistency() -> None:
    with plugged(small_settings(payload_alignment_log2=2), PatternRenderer(6, 5)) as (_, host):
        sirm = host.u64(host.u64(0x01D8) + SBRM_SIRM_ADDRESS)
        assert host.write_u32(sirm + SI_SIZE, 6) == STATUS_PAYLOAD_NOT_ALIGNED
        for offset, value in ((SI_MAX_LEADER, 64), (SI_SIZE, 16), (SI_COUNT, 1), (SI_MAX_TRAILER, 64)):
            assert host.write_u32(sirm + offset, value) == SUCCESS
        assert host.write_u32(sirm + SI_CONTROL, 1) == STATUS_SI_INCONSISTENT  # 16 bytes < 60-byte payload
        assert host.write_u32(sirm + SI_COUNT, 4) == SUCCESS
        assert host.write_u32(sirm + SI_CONTROL, 1) == SUCCESS
        assert host.write_u32(sirm + SI_SIZE, 32) == ACCESS_DENIED  # locked while the stream is enabled


def test_free_run_skips_to_the_newest_frame() -> None:
    render = PatternRenderer(6, 5)
    with plugged(small_settings(frame_rate_hz=500.0), render) as (camera, host):
        start_stream(host, 64, 1, 0, 0)
        first = read_block(host, [64]).leader[3]
        time.sleep(0.05)  # 50 ms at 500 Hz: at least 25 frames complete meanwhile
        second = read_block(host, [64]).leader[3]
        assert second - first >= 2
        counters = camera.counters
        assert counters.blocks_sent == 2
        assert counters.frames_skipped == second - 1  # every id below `second` except `first` was skipped
        assert counters.frames_produced >= second + 1
        assert render.calls == [first, second]  # skipped frames are never rendered
        with pytest.raises(KeyError):
            camera.truth(second - 1)
        ids = [read_block(host, [64]).leader[3] for _ in range(3)]
        assert ids[0] > second and ids[1] > ids[0] and ids[2] > ids[1]


def test_software_trigger_queues_at_most_two_frames() -> None:
    with plugged(small_settings(exposure_us=10.0), PatternRenderer(6, 5)) as (camera, host):
        _, f = feature_nodes(host)
        assert host.write_u32(f["TriggerSoftware"][0], 1) == ACCESS_DENIED  # TriggerMode is Off
        assert host.write_u32(f["TriggerMode"][0], 1) == SUCCESS
        start_stream(host, 64, 1, 0, 0)
        assert host.write_u32(f["Width"][0], 4) == ACCESS_DENIED  # locked while acquiring
        with pytest.raises(usb.core.USBTimeoutError):
            host.dev.read(0x82, 64, 30)  # no trigger, no frame
        for _ in range(3):
            assert host.write_u32(f["TriggerSoftware"][0], 1) == SUCCESS
        assert [read_block(host, [64]).leader[3] for _ in range(2)] == [0, 1]
        assert camera.counters.triggers_ignored == 1
        with pytest.raises(usb.core.USBTimeoutError):
            host.dev.read(0x82, 64, 30)
        assert host.write_u32(f["TriggerSoftware"][0], 1) == SUCCESS
        assert read_block(host, [64]).leader[3] == 2


def test_size_change_while_streaming_discards_what_does_not_fit() -> None:
    with plugged(small_settings(pixel_format="Mono8"), PatternRenderer(6, 5)) as (camera, host):
        start_stream(host, 30, 1, 0, 0)  # exactly the 30-byte Mono8 payload
        assert read_block(host, [30]).trailer[4] == 0
        bigger = PatternRenderer(8, 5)
        camera.set_size(8, 5, render=bigger)
        block = read_block(host, [30])
        assert block.leader[8:10] == (8, 5)
        t_status, valid, size_y = block.trailer[4], block.trailer[6], block.trailer[7]
        assert (t_status, valid, size_y) == (STATUS_DATA_DISCARDED, 30, 30 // 8)
        assert block.payload == bigger.expected(block.leader[3]).astype("u1").tobytes()[:30]


def test_control_and_stream_from_two_threads() -> None:
    with plugged(small_settings(frame_rate_hz=1000.0), PatternRenderer(6, 5)) as (_, host):
        start_stream(host, 64, 1, 0, 0)
        ids: list[int] = []
        errors: list[BaseException] = []

        def reader() -> None:
            try:
                ids.extend(read_block(host, [64]).leader[3] for _ in range(20))
            except BaseException as error:  # reported below
                errors.append(error)

        thread = threading.Thread(target=reader, name="sim-u3v-test-reader")
        thread.start()
        try:
            for i in range(50):
                assert host.u32(0) == 0x0001_0000, i
        finally:
            thread.join(timeout=30)
        assert not errors and len(ids) == 20 and ids == sorted(set(ids))


# --- faults ------------------------------------------------------------------------------------
def test_timeout_fault_then_stream_resumes() -> None:
    with plugged(small_settings(), PatternRenderer(6, 5)) as (camera, host):
        start_stream(host, 64, 1, 0, 0)
        camera.faults.timeout_reads = 2
        for _ in range(2):
            with pytest.raises(usb.core.USBTimeoutError) as timed_out:
                host.dev.read(0x82, 64, 10)
            assert (timed_out.value.errno, timed_out.value.backend_error_code) == (errno.ETIMEDOUT, -7)
        assert read_block(host, [64]).leader[0] == LEADER_MAGIC


def test_stall_until_clear_halt_drops_the_block_in_flight() -> None:
    with plugged(small_settings(), PatternRenderer(6, 5)) as (camera, host):
        start_stream(host, 16, 4, 0, 0)  # 60-byte Mono12 payload: 4 x 16
        interrupted = LEADER.unpack(bytes(host.dev.read(0x82, 64, TIMEOUT_MS)))[3]
        camera.faults.stall_next = True
        for _ in range(2):  # halted until cleared
            with pytest.raises(usb.core.USBError) as stalled:
                host.dev.read(0x82, 64, TIMEOUT_MS)
            assert stalled.value.errno == errno.EPIPE
        host.dev.clear_halt(0x82)
        block = read_block(host, [16] * 4)
        assert block.leader[0] == LEADER_MAGIC and block.leader[3] > interrupted


def test_partial_transfer_is_short_and_trailer_keeps_full_size() -> None:
    with plugged(small_settings(), PatternRenderer(6, 5)) as (camera, host):
        start_stream(host, 16, 4, 0, 0)
        camera.faults.partial_transfer = True
        block = read_block(host, [16] * 4)
        assert block.transfer_lengths == (8, 16, 16, 12)  # first payload transfer cut in half
        assert block.trailer[6] == 60  # the device believes it sent everything
        assert read_block(host, [16] * 4).transfer_lengths == (16, 16, 16, 12)  # one-shot


@pytest.mark.parametrize("where", ["leader", "trailer"])
@pytest.mark.parametrize("how", ["magic", "block_id", "size"])
def test_corrupted_leader_or_trailer(where: str, how: str) -> None:
    with plugged(small_settings(), PatternRenderer(6, 5)) as (camera, host):
        start_stream(host, 64, 1, 0, 0)
        setattr(camera.faults, f"corrupt_{where}", how)
        raw = [bytes(host.dev.read(0x82, 64, TIMEOUT_MS)) for _ in range(3)]  # leader, payload, trailer
        bad, good = (raw[0], raw[2]) if where == "leader" else (raw[2], raw[0])
        size = LEADER.size if where == "leader" else TRAILER.size
        magic = LEADER_MAGIC if where == "leader" else TRAILER_MAGIC
        good_id = struct.unpack_from("<Q", good, 8)[0]
        if how == "size":
            assert len(bad) == 20 and struct.unpack_from("<H", bad, 6)[0] == size
        else:
            assert len(bad) == size
            bad_magic, bad_id = struct.unpack_from("<I", bad)[0], struct.unpack_from("<Q", bad, 8)[0]
            assert (bad_magic != magic) == (how == "magic")
            assert bad_id == good_id + (1 if how == "block_id" else 0)
        assert read_block(host, [64]).trailer[0] == TRAILER_MAGIC  # the next block is intact


def test_unplug_and_replug() -> None:
    render = PatternRenderer(6, 5)
    camera = SimulatedU3VCamera(small_settings(), render)
    backend = SimulatedUsbBackend([camera])
    old = usb.core.find(backend=backend, custom_match=is_u3v)
    host = Host(old)
    _, f = feature_nodes(host)
    assert host.write_u32(f["TriggerMode"][0], 1) == SUCCESS
    start_stream(host, 64, 1, 0, 0)
    outcome: list[BaseException] = []

    def blocked_reader() -> None:  # waits for a trigger that never comes
        try:
            old.read(0x82, 64, 10_000)
        except usb.core.USBError as error:
            outcome.append(error)

    thread = threading.Thread(target=blocked_reader, name="sim-u3v-test-unplug")
    thread.start()
    time.sleep(0.02)
    camera.unplug()
    thread.join(timeout=30)
    assert not thread.is_alive() and outcome and outcome[0].errno == errno.ENODEV
    assert list(usb.core.find(find_all=True, backend=backend)) == []
    for call in (lambda: old.write(0x01, command(READMEM, 1, struct.pack("<QHH", 0, 0, 4))),
                 lambda: old.read(0x81, 64, 10), lambda: old.clear_halt(0x82)):
        with pytest.raises(usb.core.USBError) as gone:
            call()
        assert gone.value.errno == errno.ENODEV
    camera.replug()
    new = usb.core.find(backend=backend, custom_match=is_u3v)
    assert new is not None and new.address != old.address
    with pytest.raises(usb.core.USBError) as stale:  # a handle from before the replug stays dead
        old.read(0x81, 64, 10)
    assert stale.value.errno == errno.ENODEV
    fresh = Host(new)
    assert fresh.u32(f["TriggerMode"][0]) == 0  # powered on anew
    assert fresh.u32(f["Width"][0]) == 6
    assert fresh.write_u32(f["Width"][0], 4) == SUCCESS
    new.reset()  # USB reset: power-on state again, same enumeration
    assert fresh.u32(f["Width"][0]) == 6
    usb.util.dispose_resources(old)
    usb.util.dispose_resources(new)


# --- robustness ---------------------------------------------------------------------------------
@settings(max_examples=150, deadline=None)
@given(st.one_of(st.binary(max_size=80),
                 st.binary(max_size=60).map(lambda b: struct.pack("<I", PREFIX) + b)))
def test_arbitrary_control_bytes_never_crash_the_device(packet: bytes) -> None:
    camera = SimulatedU3VCamera(small_settings(), PatternRenderer(6, 5))
    dev = usb.core.find(backend=SimulatedUsbBackend([camera]), custom_match=is_u3v)
    try:
        assert dev.write(0x01, packet, TIMEOUT_MS) == len(packet)
        try:
            raw = bytes(dev.read(0x81, 4096, 1))  # processing is synchronous: an ack is already queued
        except usb.core.USBTimeoutError:
            raw = None
        if raw is not None:
            ack = parse_ack(raw)  # well-formed: prefix and length field agree with the bytes
            assert len(packet) >= 4 and packet[:4] == struct.pack("<I", PREFIX)
            header = packet[:12].ljust(12, b"\0")
            _, flags, command_id, scd_length, request_id = struct.unpack("<IHHHH", header)
            assert ack.request_id == request_id and ack.command_id == (command_id + 1) & 0xFFFF
            if ack.status == SUCCESS:  # only a genuinely valid command succeeds
                assert command_id in (READMEM, WRITEMEM) and scd_length == len(packet) - 12
        assert Host(dev).u32(0) == 0x0001_0000  # and the device still answers
    finally:
        usb.util.dispose_resources(dev)


# --- SFNC features a generic GenICam consumer expects ----------------------------------------------
# Names, node types and categories from the GenICam Standard Features Naming Convention (SFNC 2.6):
# Device Control (identity strings, DeviceUserID writable), Acquisition Control (AcquisitionMode with
# Continuous), Transport Layer Control (PayloadSize, read-only; TLParamsLocked, 0/1, which locks the
# features that change the payload while set). A U3V device's identity strings are the ABRM's
# (offsets from the protocol sheet).
ABRM_STRINGS = {"DeviceVendorName": 0x0004, "DeviceModelName": 0x0044, "DeviceFamilyName": 0x0084,
                "DeviceVersion": 0x00C4, "DeviceManufacturerInfo": 0x0104, "DeviceSerialNumber": 0x0144,
                "DeviceUserID": 0x0184}
SFNC_CATEGORIES = {"DeviceControl": set(ABRM_STRINGS), "AcquisitionControl": {"AcquisitionMode"},
                   "TransportLayerControl": {"PayloadSize", "TLParamsLocked"}}


def test_xml_carries_the_sfnc_features_generic_consumers_expect() -> None:
    settings_ = small_settings(width=9, height=4, model="WaveCam U3V-Sim", manufacturer="wavestack")
    with plugged(settings_, PatternRenderer(9, 4)) as (_, host):
        root, features = feature_nodes(host)
        nodes = {node.get("Name"): node for node in root}
        categories = {name: {p.text for p in nodes[name].iter(NS + "pFeature")} for name in SFNC_CATEGORIES}
        for category, members in SFNC_CATEGORIES.items():
            assert members <= categories[category], category
            assert category in {p.text for p in nodes["Root"].iter(NS + "pFeature")}
        # identity: StringReg nodes on the ABRM strings, 64 bytes, read-only but for DeviceUserID
        for name, offset in ABRM_STRINGS.items():
            node = nodes[name]
            assert node.tag == NS + "StringReg" and int(node.findtext(NS + "Address"), 0) == offset
            assert int(node.findtext(NS + "Length")) == 64 and node.findtext(NS + "pPort") == "Device"
            assert node.findtext(NS + "AccessMode") == ("RW" if name == "DeviceUserID" else "RO")
        text = {name: host.read(offset, 64).rstrip(b"\0").decode() for name, offset in ABRM_STRINGS.items()}
        assert (text["DeviceVendorName"], text["DeviceModelName"], text["DeviceSerialNumber"]) == \
            ("wavestack", "WaveCam U3V-Sim", "SIM-A")
        assert host.writemem(ABRM_STRINGS["DeviceUserID"], b"bench-1".ljust(64, b"\0")).status == SUCCESS
        assert host.read(ABRM_STRINGS["DeviceUserID"], 7) == b"bench-1"
        # PayloadSize: read-only Integer, width * height * bytes per pixel of the format in force
        assert nodes["PayloadSize"].tag == NS + "Integer" and features["PayloadSize"][2] == "RO"
        assert host.u32(features["PayloadSize"][0]) == 9 * 4 * 2  # Mono12 travels in two bytes
        assert host.write_u32(features["PixelFormat"][0], MONO8) == SUCCESS
        assert host.u32(features["PayloadSize"][0]) == 9 * 4 * 1
        assert host.write_u32(features["PayloadSize"][0], 1) == WRITE_PROTECT
        # AcquisitionMode: Enumeration with Continuous, which it reads as
        mode = nodes["AcquisitionMode"]
        entries = {e.get("Name"): int(e.findtext(NS + "Value"), 0) for e in mode.iter(NS + "EnumEntry")}
        assert mode.tag == NS + "Enumeration" and "Continuous" in entries and features["AcquisitionMode"][2] == "RW"
        assert host.u32(features["AcquisitionMode"][0]) == entries["Continuous"]
        assert host.write_u32(features["AcquisitionMode"][0], max(entries.values()) + 1) == INVALID_PARAMETER
        # TLParamsLocked: Integer 0..1; while 1, the features that change the payload refuse writes
        locked = nodes["TLParamsLocked"]
        assert locked.tag == NS + "Integer" and (locked.findtext(NS + "Min"), locked.findtext(NS + "Max")) == ("0", "1")
        for name in ("Width", "Height", "PixelFormat"):
            assert nodes[name].findtext(NS + "pIsLocked") == "TLParamsLocked"
        address = features["TLParamsLocked"][0]
        assert host.u32(address) == 0 and host.write_u32(address, 2) == INVALID_PARAMETER
        assert host.write_u32(address, 1) == SUCCESS
        assert host.write_u32(features["Width"][0], 8) == ACCESS_DENIED
        assert host.write_u32(features["PixelFormat"][0], MONO16) == ACCESS_DENIED
        assert host.write_u32(features["AcquisitionMode"][0],
                              entries["Continuous"]) == SUCCESS  # not a transport-layer parameter
        assert host.write_u32(address, 0) == SUCCESS and host.write_u32(features["Width"][0], 8) == SUCCESS
        assert host.u32(features["PayloadSize"][0]) == 8 * 4 * 1

