"""Property tests of the USB3 Vision parsers: hostile bytes, round trips, driver against simulator.

What is parsed, host side: GenCP acknowledges (:mod:`~wavestack.drivers.u3v.gencp`), the bootstrap
registers and manifest (:mod:`~wavestack.drivers.u3v.bootstrap`), the GenICam XML
stream leaders, trailers and payloads
(:mod:`~wavestack.drivers.u3v.image_block`, :mod:`~wavestack.drivers.u3v.stream`). Device side: the
simulator's GenCP command parser (:mod:`wavestack.simulators.u3v.gencp_device`) over its register
space. Each must return a value or raise :class:`ProtocolError`; the two sides, written apart on
purpose, must understand each other.
"""

from __future__ import annotations

from collections.abc import Callable

import hashlib
import math
import struct
import tracemalloc

import numpy as np
import pytest
from fuzz import fuzz_settings
from hypothesis import example, given
from hypothesis import strategies as st

from camera_hooks import AcceptingHooks
from wavestack.drivers.errors import ProtocolError
from wavestack.drivers.u3v import bootstrap as bs
from wavestack.drivers.u3v import gencp
from wavestack.drivers.genicam import NodeMap
from wavestack.drivers.u3v.stream import (AssembledBlock, BlockAssembler, DiscardedBlock, Leader, check_block,
                                          decode_pixels, parse_leader, parse_trailer)
from wavestack.simulators.u3v import gencp_device as sim_gencp
from wavestack.simulators.u3v import stream_device as sim_stream
from wavestack.simulators.u3v.device_description import FEATURES, DeviceIdentity
from wavestack.simulators.u3v.genicam_xml import genicam_xml, manifest_file
from wavestack.simulators.u3v.register_map import GenCPStatus, Register, RegisterMap
from wavestack.simulators.u3v.registers import build_register_map

DEVICE = "U3V camera (fuzz)"
IDENTITY = DeviceIdentity("Wavestack", "SimCam", "Sim", "1.0", "fuzz", "0001", 200, 1024, 1024)
MONO = (0x01080001, 0x01100005, 0x01100007)


def _mutations(valid: bytes) -> st.SearchStrategy[bytes]:
    """Truncations, single-byte changes and trailing garbage of a valid message."""
    cut = st.integers(0, len(valid)).map(lambda n: valid[:n])
    flip = st.tuples(st.integers(0, max(len(valid) - 1, 0)), st.integers(0, 255)).map(
        lambda p: valid[:p[0]] + bytes([p[1]]) + valid[p[0] + 1:])
    extra = st.binary(min_size=1, max_size=16).map(lambda tail: valid + tail)
    return st.one_of(cut, flip, extra)


# ------------------------------------------------------------------------------- GenCP acknowledges
def _ack(status: int, command_id: int, request_id: int, scd: bytes) -> bytes:
    return sim_gencp.Acknowledge(status, command_id, request_id, scd).to_bytes()


valid_acks = st.builds(_ack, st.integers(0, 0xFFFF), st.sampled_from([0x0801, 0x0803, 0x0805, 0x1234]),
                       st.integers(0, 0xFFFF), st.binary(max_size=40))


@fuzz_settings(300)
@given(packet=st.one_of(st.binary(max_size=64), valid_acks.flatmap(_mutations)))
def test_acknowledge_parser_returns_or_raises_protocol_error(packet: bytes) -> None:
    try:
        ack = gencp.parse_acknowledge(packet, DEVICE)
    except ProtocolError:
        return
    assert len(ack.scd) == len(packet) - gencp.HEADER_SIZE == struct.unpack_from("<H", packet, 8)[0]
    assert struct.unpack_from("<I", packet)[0] == gencp.PREFIX
    for reader in (gencp.pending_timeout_ms, gencp.bytes_written):
        try:
            assert 0 <= reader(ack, DEVICE) <= 0xFFFF
        except ProtocolError:
            pass
    assert gencp.status_name(ack.status)  # never raises, names unknown codes too


@fuzz_settings(300)
@given(status=st.integers(0, 0xFFFF), command_id=st.integers(0, 0xFFFF), request_id=st.integers(0, 0xFFFF),
       scd=st.binary(max_size=64))
def test_simulator_acknowledges_parse_back_to_their_fields(status: int, command_id: int, request_id: int,
                                                          scd: bytes) -> None:
    ack = gencp.parse_acknowledge(_ack(status, command_id, request_id, scd), DEVICE)
    assert (ack.status, ack.command_id, ack.request_id, ack.scd) == (status, command_id, request_id, scd)


@fuzz_settings(300)
@given(max_ack=st.one_of(st.integers(0, 2**32 - 1), st.sampled_from([0, 12, 16, 1024, 65547, 65548, 2**32 - 1])))
def test_the_acknowledge_buffer_holds_every_acknowledge_and_no_more(max_ack: int) -> None:
    size = gencp.ack_buffer_size(max_ack)
    assert size <= gencp.HEADER_SIZE + 0xFFFF  # a 4 GiB SBRM length field must not size a 4 GiB read
    assert size == min(max_ack, gencp.HEADER_SIZE + 0xFFFF)  # ... and every acknowledge still fits
    try:
        assert gencp.HEADER_SIZE + gencp.max_read_chunk(max_ack) <= size
    except ValueError:
        assert max_ack < gencp.HEADER_SIZE + 4


def _memory_map() -> RegisterMap:
    """Three read/write cells and a read-only one, with a gap: 0x100 (4 B), 0x104 (8 B), 0x10C RO, 0x200."""
    cells: dict[int, bytearray] = {0x100: bytearray(4), 0x104: bytearray(8), 0x10C: bytearray(b"ROCELL!!"),
                                   0x200: bytearray(16)}

    def register(address: int, access: str) -> Register:
        cell = cells[address]

        def write(data: bytes) -> GenCPStatus:
            cell[:] = data
            return GenCPStatus.SUCCESS
        return Register(f"r{address:x}", address, len(cell), access, lambda: bytes(cell),  # type: ignore[arg-type]
                        write if access != "RO" else None)
    return RegisterMap([register(0x100, "RW"), register(0x104, "RW"), register(0x10C, "RO"),
                        register(0x200, "WO")])


addresses = st.one_of(st.integers(0xF8, 0x220), st.sampled_from([0x100, 0x104, 0x10C, 0x200]),
                      st.integers(0, 2**64 - 1))


@fuzz_settings(300)
@given(request_id=st.integers(0, 0xFFFF), address=addresses, length=st.integers(1, 0xFFFF))
def test_a_readmem_the_driver_encodes_is_executed_and_acknowledged_as_the_driver_reads_it(
        request_id: int, address: int, length: int) -> None:
    registers = _memory_map()
    device = sim_gencp.GenCPDevice(registers, max_command_bytes=1024, max_ack_bytes=1024)
    reply = device.execute(gencp.encode_readmem(request_id, address, length))
    assert reply is not None
    ack = gencp.parse_acknowledge(reply.to_bytes(), DEVICE)
    assert (ack.command_id, ack.request_id) == (gencp.READMEM_ACK, request_id)
    if gencp.HEADER_SIZE + length > 1024:
        assert ack.status == gencp.GenCPStatus.INVALID_PARAMETER and ack.scd == b""
        return
    status, data = registers.read(address, length)
    assert (ack.status, ack.scd) == (status, data)
    assert len(ack.scd) == (length if ack.succeeded else 0)


@fuzz_settings(300)
@given(request_id=st.integers(0, 0xFFFF), address=addresses, data=st.binary(min_size=1, max_size=40))
@example(request_id=1, address=0x200, data=bytes(16))  # a write-only register: GenCP cannot read it back
def test_a_writemem_the_driver_encodes_is_executed_and_acknowledged_as_the_driver_reads_it(
        request_id: int, address: int, data: bytes) -> None:
    registers = _memory_map()
    device = sim_gencp.GenCPDevice(registers, max_command_bytes=1024, max_ack_bytes=1024)
    reply = device.execute(gencp.encode_writemem(request_id, address, data))
    assert reply is not None
    ack = gencp.parse_acknowledge(reply.to_bytes(), DEVICE)
    assert (ack.command_id, ack.request_id) == (gencp.WRITEMEM_ACK, request_id)
    written = gencp.bytes_written(ack, DEVICE)
    if ack.succeeded:
        assert written == len(data)
        write_only = {r.address: r for r in registers if r.access == "WO"}
        if address in write_only:  # GenCP refuses to read it back: look at the register itself
            assert registers.read(address, len(data))[0] == GenCPStatus.ACCESS_DENIED
            assert write_only[address].read() == data
        else:
            assert registers.read(address, len(data)) == (GenCPStatus.SUCCESS, data)
    else:
        assert written == 0


valid_commands = st.one_of(
    st.builds(gencp.encode_readmem, st.integers(0, 0xFFFF), addresses, st.integers(1, 0xFFFF)),
    st.builds(gencp.encode_writemem, st.integers(0, 0xFFFF), addresses, st.binary(min_size=1, max_size=24)))


@fuzz_settings(300)
@given(packet=st.one_of(st.binary(max_size=48), valid_commands.flatmap(_mutations)))
def test_the_simulated_device_answers_any_command_bytes_with_a_parseable_acknowledge_or_none(packet: bytes) -> None:
    device = sim_gencp.GenCPDevice(_memory_map(), max_command_bytes=1024, max_ack_bytes=1024)
    reply = device.execute(packet)
    if reply is None:
        return
    ack = gencp.parse_acknowledge(reply.to_bytes(), DEVICE)
    if len(packet) >= gencp.HEADER_SIZE:  # an intact header's request id is echoed
        assert ack.request_id == struct.unpack_from("<H", packet, 10)[0]


# ------------------------------------------------------------------------- bootstrap and manifest
@fuzz_settings(300)
@given(data=st.binary(max_size=0x220))
def test_bootstrap_decoders_return_or_raise_protocol_error(data: bytes) -> None:
    for decode in (bs.decode_abrm, bs.decode_sbrm, bs.decode_sirm, bs.decode_manifest_count,
                   bs.decode_manifest_entry):
        try:
            decode(data, DEVICE)
        except ProtocolError:
            pass


sirm_fields = st.tuples(st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1), st.integers(0, 2**64 - 1),
                        *[st.integers(0, 2**32 - 1)] * 8)
hostile_sirms = st.one_of(
    sirm_fields.map(lambda f: struct.pack("<IIQIIIIIIII", *f)),
    st.tuples(st.integers(0, 255), st.integers(1, 2**40), st.integers(0, 4096), st.integers(0, 4096)).map(
        lambda f: struct.pack("<IIQII", f[0] << 24, 0, f[1], f[2], f[3]) + bytes(24)))


@fuzz_settings(300)
@given(data=hostile_sirms)
def test_a_sirm_that_decodes_gives_transfer_sizes_the_sirm_can_hold_and_bounded_reads(data: bytes) -> None:
    """The host writes the derived sizes into u32 registers and sizes its bulk reads from them."""
    try:
        sirm = bs.decode_sirm(data, DEVICE)
    except ProtocolError:
        return
    stream_transfer = 1 << 20  # the acquisition's largest stream transfer (drivers/u3v/acquisition.py)
    sizes = bs.compute_transfer_sizes(sirm.required_payload_size, max(sirm.required_leader_size, 52),
                                      max(sirm.required_trailer_size, 32), sirm.alignment,
                                      max(stream_transfer, sirm.alignment))
    fields = (sizes.max_leader_size, sizes.payload_size, sizes.payload_count, sizes.final1_size, sizes.final2_size,
              sizes.max_trailer_size)
    assert all(0 <= value <= 0xFFFF_FFFF for value in fields)
    assert sizes.payload_capacity >= sirm.required_payload_size
    assembler = BlockAssembler(sizes, sirm.required_payload_size, DEVICE)
    assert assembler.next_read_size() <= 2 * stream_transfer


def test_a_sirm_with_an_absurd_alignment_is_refused() -> None:
    # regression: SI info 0xFF000000 announced a 2**255-byte alignment; the transfer sizes derived
    # from it did not fit the u32 SIRM registers (struct.error) and sized a 2**255-byte read buffer
    with pytest.raises(ProtocolError, match="alignment"):
        bs.decode_sirm(struct.pack("<IIQII", 0xFF << 24, 0, 4096, 52, 32) + bytes(24), DEVICE)


class _RegisterPort:
    def __init__(self, read: Callable[[int, int], bytes]) -> None:
        self.read = read

    def write(self, address: int, data: bytes) -> None:
        raise AssertionError("nothing is written here")


printable = st.text(st.characters(min_codepoint=33, max_codepoint=126), min_size=1, max_size=64)


@fuzz_settings(30)
@given(manufacturer=printable, model=printable, serial=printable, zipped=st.booleans())
def test_the_simulators_bootstrap_manifest_and_xml_decode_in_the_driver(manufacturer: str, model: str, serial: str,
                                                                      zipped: bool) -> None:
    identity = DeviceIdentity(manufacturer, model, "Sim", "1.0", "fuzz", serial, 200, 1024, 1024)
    registers = build_register_map(identity, AcceptingHooks(), zipped_xml=zipped)

    def read(address: int, length: int) -> bytes:
        status, data = registers.read(address, length)
        assert status == GenCPStatus.SUCCESS
        return data
    abrm = bs.decode_abrm(read(bs.ABRM_ADDRESS, bs.ABRM_SIZE), DEVICE)
    assert (abrm.manufacturer, abrm.model, abrm.serial_number) == (manufacturer, model, serial)
    sbrm = bs.decode_sbrm(read(abrm.sbrm_address, bs.SBRM_SIZE), DEVICE)
    assert (sbrm.max_command_transfer_length, sbrm.max_ack_transfer_length) == (1024, 1024)
    assert bs.decode_manifest_count(read(abrm.manifest_table_address, 8), DEVICE) == 1
    entry = bs.decode_manifest_entry(read(abrm.manifest_table_address + 8, 64), DEVICE)
    file = read(entry.address, entry.size)
    assert hashlib.sha1(file).digest() == entry.sha1 and entry.file_format == int(zipped)
    node_map = NodeMap.from_xml(file, device=DEVICE, zipped=bool(entry.file_format))
    node_map.attach(_RegisterPort(read))
    for spec in FEATURES:
        assert spec.name in node_map
        info = node_map.info(spec.name)
        assert info.kind == {"Integer": "integer", "Float": "float", "Enumeration": "enumeration",
                             "Command": "command"}[spec.kind]


# ------------------------------------------------------------------------------------ image stream
@st.composite
def formats(draw: st.DrawFn) -> sim_stream.ImageFormat:
    return sim_stream.ImageFormat(draw(st.integers(1, 24)), draw(st.integers(1, 12)), draw(st.sampled_from(MONO)))


@fuzz_settings(300)
@given(block_id=st.integers(0, 2**64 - 1), timestamp=st.integers(0, 2**64 - 1),
       width=st.integers(0, 2**32 - 1), height=st.integers(0, 2**32 - 1), code=st.integers(0, 2**32 - 1),
       valid=st.integers(0, 2**64 - 1), status=st.integers(0, 0xFFFF))
def test_simulator_leaders_and_trailers_parse_back_to_their_fields(block_id: int, timestamp: int, width: int,
                                                                 height: int, code: int, valid: int,
                                                                 status: int) -> None:
    leader = parse_leader(sim_stream.encode_leader(block_id, timestamp, sim_stream.ImageFormat(width, height, code)),
                          DEVICE)
    assert (leader.block_id, leader.timestamp, leader.pixel_format, leader.size_x, leader.size_y) == (
        block_id, timestamp, code, width, height)
    trailer = parse_trailer(sim_stream.encode_trailer(block_id, valid, height & 0xFFFFFFFF, status), DEVICE)
    assert (trailer.block_id, trailer.status, trailer.valid_payload_size, trailer.size_y) == (
        block_id, status, valid, height)


valid_leaders = st.builds(sim_stream.encode_leader, st.integers(0, 2**64 - 1), st.integers(0, 2**64 - 1), formats())
valid_trailers = st.builds(sim_stream.encode_trailer, st.integers(0, 2**64 - 1), st.integers(0, 2**64 - 1),
                           st.integers(0, 2**32 - 1))


@fuzz_settings(300)
@given(leader_bytes=st.one_of(st.binary(max_size=80), valid_leaders.flatmap(_mutations)),
       trailer_bytes=st.one_of(st.binary(max_size=48), valid_trailers.flatmap(_mutations)),
       received=st.integers(0, 2**20), limit=st.integers(0, 2**20))
def test_leaders_and_trailers_return_or_raise_protocol_error(leader_bytes: bytes, trailer_bytes: bytes,
                                                            received: int, limit: int) -> None:
    try:
        leader = parse_leader(leader_bytes, DEVICE)
        trailer = parse_trailer(trailer_bytes, DEVICE)
        assert check_block(leader, trailer, received, limit, DEVICE) <= min(received, limit)
    except ProtocolError:
        pass


@fuzz_settings(300)
@given(leader_bytes=valid_leaders.flatmap(_mutations), payload=st.binary(max_size=600))
def test_payload_decoding_returns_an_image_or_raises_protocol_error_without_large_allocations(
        leader_bytes: bytes, payload: bytes) -> None:
    try:
        leader = parse_leader(leader_bytes, DEVICE)
    except ProtocolError:
        return
    tracemalloc.start()
    try:
        pixels = decode_pixels(payload, leader, DEVICE)
    except ProtocolError:
        pixels = None
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert peak < 1 << 16  # a 4-billion-pixel leader must not allocate for its image
    if pixels is not None:
        assert pixels.shape == (leader.size_y, leader.size_x) and pixels.nbytes <= len(payload)


@fuzz_settings(100)
@given(fmt=formats(), seed=st.integers(0, 2**32 - 1), log2_alignment=st.integers(0, 6),
       max_transfer=st.integers(64, 512), block_id=st.integers(0, 2**64 - 1))
def test_a_block_the_simulator_streams_assembles_into_the_same_pixels(
        fmt: sim_stream.ImageFormat, seed: int, log2_alignment: int, max_transfer: int, block_id: int) -> None:
    maximum = 255 if fmt.pixel_format == MONO[0] else (4095 if fmt.pixel_format == MONO[1] else 65535)
    pixels = np.random.default_rng(seed).integers(0, maximum + 1, (fmt.height, fmt.width))
    payload = sim_stream.encode_payload(pixels, fmt)
    alignment = 1 << log2_alignment
    sizes = bs.compute_transfer_sizes(fmt.payload_size, 52, 32, alignment, max(max_transfer, alignment))
    assembler = BlockAssembler(sizes, fmt.payload_size, DEVICE)
    padded = payload.ljust(sizes.payload_capacity, b"\0")
    chunks = [padded[i * sizes.payload_size:(i + 1) * sizes.payload_size] for i in range(sizes.payload_count)]
    offset = sizes.payload_size * sizes.payload_count
    for final in (sizes.final1_size, sizes.final2_size):
        if final:
            chunks.append(padded[offset:offset + final])
            offset += final
    outcomes = [assembler.feed(sim_stream.encode_leader(block_id, 7, fmt))]
    outcomes += [assembler.feed(chunk) for chunk in chunks]
    outcomes.append(assembler.feed(sim_stream.encode_trailer(block_id, fmt.payload_size, fmt.height)))
    assert outcomes[:-1] == [None] * (len(outcomes) - 1)
    block = outcomes[-1]
    assert isinstance(block, AssembledBlock) and block.leader.block_id == block_id
    assert np.array_equal(block.pixels, pixels) and block.pixels.shape == (fmt.height, fmt.width)


transfers = st.one_of(st.binary(max_size=80), valid_leaders.flatmap(_mutations), valid_trailers.flatmap(_mutations))


@fuzz_settings(150)
@given(stream=st.lists(transfers, max_size=12))
def test_the_assembler_survives_any_transfer_sequence(stream: list[bytes]) -> None:
    sizes = bs.compute_transfer_sizes(24 * 12 * 2, 52, 32, 1, 128)
    assembler = BlockAssembler(sizes, 24 * 12 * 2, DEVICE)
    for transfer in stream:
        outcome = assembler.feed(transfer)
        assert outcome is None or isinstance(outcome, (AssembledBlock, DiscardedBlock))
        assert assembler.next_read_size() >= 52
        if isinstance(outcome, AssembledBlock):
            assert isinstance(outcome.leader, Leader) and outcome.pixels.size <= 24 * 12
