"""USB3 Vision sans-I/O modules against hand-built bytes (layouts taken from the protocol sheet)."""

from __future__ import annotations

import io
import struct
import zipfile

import numpy as np
import pytest
from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.drivers import ProtocolError
from wavestack.drivers.u3v import bootstrap as bs
from wavestack.drivers.u3v import gencp
from wavestack.drivers.u3v.stream import (AssembledBlock, BlockAssembler, DiscardedBlock, check_block, decode_pixels,
                                          parse_leader, parse_trailer)

DEV = "test camera"
PREFIX = 0x43563355
MONO8, MONO12, MONO16 = 0x01080001, 0x01100005, 0x01100007


# ------------------------------------------------------------------------------------ GenCP
def ack(status: int, command_id: int, request_id: int, scd: bytes = b"", prefix: int = PREFIX) -> bytes:
    return struct.pack("<IHHHH", prefix, status, command_id, len(scd), request_id) + scd


def test_readmem_command_layout() -> None:
    packet = gencp.encode_readmem(7, 0x1234_5678_9ABC, 64)
    assert packet == struct.pack("<IHHHHQHH", PREFIX, 0x4000, 0x0800, 12, 7, 0x1234_5678_9ABC, 0, 64)


def test_writemem_command_layout() -> None:
    packet = gencp.encode_writemem(0xFFFF, 0x40, b"\x01\x02\x03\x04")
    assert packet == struct.pack("<IHHHHQ", PREFIX, 0x4000, 0x0802, 12, 0xFFFF, 0x40) + b"\x01\x02\x03\x04"


@pytest.mark.parametrize("bad", [lambda: gencp.encode_readmem(1, 0, 0), lambda: gencp.encode_readmem(1, 0, 65536),
                                 lambda: gencp.encode_readmem(70000, 0, 4), lambda: gencp.encode_writemem(1, -1, b"x"),
                                 lambda: gencp.encode_writemem(1, 0, b"")])
def test_encoders_refuse_bad_arguments(bad) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError):
        bad()


def test_request_ids_wrap_skipping_zero() -> None:
    assert gencp.next_request_id(0) == 1
    assert gencp.next_request_id(41) == 42
    assert gencp.next_request_id(0xFFFF) == 1


def test_parse_acknowledges() -> None:
    read = gencp.parse_acknowledge(ack(0, 0x0801, 9, b"abcd"), DEV)
    assert (read.status, read.command_id, read.request_id, read.scd, read.succeeded) == (0, 0x0801, 9, b"abcd", True)
    written = gencp.parse_acknowledge(ack(0, 0x0803, 3, struct.pack("<HH", 0, 8)), DEV)
    assert gencp.bytes_written(written, DEV) == 8
    pending = gencp.parse_acknowledge(ack(0, 0x0805, 3, struct.pack("<HH", 0, 1500)), DEV)
    assert gencp.pending_timeout_ms(pending, DEV) == 1500
    failed = gencp.parse_acknowledge(ack(0x8004, 0x0803, 4), DEV)
    assert not failed.succeeded and "WRITE_PROTECT" in gencp.status_name(failed.status)
    assert "0x8123" in gencp.status_name(0x8123)


@pytest.mark.parametrize("packet", [b"U3VC", ack(0, 0x0801, 1, b"xy", prefix=0x12345678), ack(0, 0x0801, 1, b"xy")[:-1],
                                    ack(0, 0x0801, 1, b"xy") + b"z"])
def test_malformed_acknowledges_raise_protocol_error(packet: bytes) -> None:
    with pytest.raises(ProtocolError) as info:
        gencp.parse_acknowledge(packet, DEV)
    assert DEV in str(info.value)


def test_wrong_scd_for_pending_and_writemem() -> None:
    with pytest.raises(ProtocolError):
        gencp.pending_timeout_ms(gencp.parse_acknowledge(ack(0, 0x0805, 1, b"\x00"), DEV), DEV)
    with pytest.raises(ProtocolError):
        gencp.bytes_written(gencp.parse_acknowledge(ack(0, 0x0801, 1, b"\x00\x00\x04\x00"), DEV), DEV)


def test_chunk_sizes_follow_the_sbrm_limits() -> None:
    # 1024-byte acknowledges hold 1024 - 12 data bytes, rounded down to whole 4-byte registers
    assert gencp.max_read_chunk(1024) == 1012
    # commands carry 12 header + 8 address bytes before the data
    assert gencp.max_write_chunk(1024) == 1004
    assert gencp.max_read_chunk(10**6) == 65532
    with pytest.raises(ValueError):
        gencp.max_read_chunk(14)


# ---------------------------------------------------------------------------------- bootstrap
def build_abrm() -> bytes:
    data = bytearray(bs.ABRM_SIZE)
    struct.pack_into("<HH", data, 0, 0, 1)  # minor 0, major 1
    for index, text in enumerate(["Wave", "Cam-1", "Fam", "1.2", "info", "SN42", "user"]):
        data[0x04 + 0x40 * index:0x04 + 0x40 * index + len(text)] = text.encode()
    struct.pack_into("<QIQQQ", data, 0x01C4, 0xABC, 250, 0x10000, 0x20000, 0x5)
    struct.pack_into("<Q", data, 0x01FC, 1)
    return bytes(data)


def test_decode_abrm() -> None:
    abrm = bs.decode_abrm(build_abrm(), DEV)
    assert abrm.gencp_version == (1, 0)
    assert (abrm.manufacturer, abrm.model, abrm.serial_number, abrm.user_name) == ("Wave", "Cam-1", "SN42", "user")
    assert (abrm.capability, abrm.max_response_time_ms) == (0xABC, 250)
    assert (abrm.manifest_table_address, abrm.sbrm_address, abrm.device_configuration) == (0x10000, 0x20000, 5)
    assert abrm.timestamp_increment_ns == 1


def test_decode_sbrm_and_sirm() -> None:
    sbrm_bytes = struct.pack("<IQQIIIQIQIQI", 0x00010000, 1, 2, 1024, 2048, 1, 0x30000, 0x30, 0x40000, 0x10, 0, 3)
    sbrm = bs.decode_sbrm(sbrm_bytes, DEV)
    assert (sbrm.max_command_transfer_length, sbrm.max_ack_transfer_length) == (1024, 2048)
    assert (sbrm.stream_channel_count, sbrm.sirm_address, sbrm.sirm_length, sbrm.current_speed) == (1, 0x30000, 0x30, 3)
    sirm_bytes = struct.pack("<IIQIIIIIIII", 6 << 24, 1, 3_000_000, 52, 32, 64, 4096, 732, 1536, 64, 64)
    sirm = bs.decode_sirm(sirm_bytes, DEV)
    assert sirm.alignment == 64 and sirm.stream_enabled
    assert (sirm.required_payload_size, sirm.required_leader_size, sirm.required_trailer_size) == (3_000_000, 52, 32)
    assert (sirm.payload_transfer_count, sirm.final_transfer1_size, sirm.max_trailer_size) == (732, 1536, 64)


def test_decode_manifest() -> None:
    sha = bytes(range(20))
    entry_bytes = struct.pack("<IIQQ20s20s", (1 << 24) | (2 << 16) | 3, (1 << 24) | (1 << 16) | 1, 0x50000, 1234,
                              sha, bytes(20))
    entry = bs.decode_manifest_entry(entry_bytes, DEV)
    assert entry.file_version == (1, 2, 3) and entry.schema_version == (1, 1)
    assert (entry.file_format, entry.address, entry.size, entry.sha1) == (1, 0x50000, 1234, sha)
    assert bs.decode_manifest_count(struct.pack("<Q", 2), DEV) == 2


@pytest.mark.parametrize("decoder,size", [(bs.decode_abrm, bs.ABRM_SIZE), (bs.decode_sbrm, bs.SBRM_SIZE),
                                          (bs.decode_sirm, bs.SIRM_SIZE), (bs.decode_manifest_entry, 64),
                                          (bs.decode_manifest_count, 8)])
def test_short_register_maps_raise(decoder, size: int) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ProtocolError):
        decoder(bytes(size - 1), DEV)


def test_transfer_sizes_example() -> None:
    # 1000 B payload, 64 B alignment, 256 B transfers: 3 x 256 = 768, rest 232 = 192 (aligned) + 40 -> 64
    sizes = bs.compute_transfer_sizes(1000, 52, 32, 64, 256)
    assert (sizes.payload_size, sizes.payload_count, sizes.final1_size, sizes.final2_size) == (256, 3, 192, 64)
    assert (sizes.max_leader_size, sizes.max_trailer_size) == (64, 64)


@fuzz_settings(200)
@given(payload=st.integers(0, 10**8), log2_alignment=st.integers(0, 12), max_factor=st.integers(1, 4096))
def test_transfer_sizes_cover_the_payload(payload: int, log2_alignment: int, max_factor: int) -> None:
    alignment = 1 << log2_alignment
    sizes = bs.compute_transfer_sizes(payload, 52, 32, alignment, alignment * max_factor)
    total = sizes.payload_size * sizes.payload_count + sizes.final1_size + sizes.final2_size
    assert payload <= total < payload + alignment  # covers the payload, wastes less than one alignment unit
    for size in (sizes.payload_size, sizes.final1_size, sizes.final2_size, sizes.max_leader_size,
                 sizes.max_trailer_size):
        assert size % alignment == 0
    assert sizes.payload_size <= alignment * max_factor
    assert sizes.max_leader_size >= 52 and sizes.max_trailer_size >= 32


# ------------------------------------------------------------------------------------ stream
def leader(block_id: int, fmt: int, width: int, height: int, padding: int = 0, timestamp: int = 99,
           magic: int = 0x4C563355, payload_type: int = 1) -> bytes:
    return struct.pack("<IHHQHHQIIIIIHH", magic, 0, 52, block_id, 0, payload_type, timestamp, fmt, width, height,
                       0, 0, padding, 0)


def trailer(block_id: int, valid: int, height: int, status: int = 0, magic: int = 0x54563355) -> bytes:
    return struct.pack("<IHHQHHQI", magic, 0, 32, block_id, status, 0, valid, height)


def image_payload(pixels: np.ndarray, padding: int) -> bytes:
    rows = [row.astype("<u2" if pixels.dtype == np.uint16 else np.uint8).tobytes() + bytes(padding) for row in pixels]
    return b"".join(rows)


@pytest.mark.parametrize("fmt,dtype,maximum", [(MONO8, np.uint8, 255), (MONO12, np.uint16, 4095),
                                               (MONO16, np.uint16, 65535)])
@pytest.mark.parametrize("padding", [0, 3])
def test_decode_pixels(fmt: int, dtype: type, maximum: int, padding: int) -> None:
    rng = np.random.default_rng(fmt + padding)
    pixels = rng.integers(0, maximum + 1, size=(5, 7)).astype(dtype)
    lead = parse_leader(leader(3, fmt, 7, 5, padding), DEV)
    payload = image_payload(pixels, padding)
    assert lead.expected_payload_size(DEV) == len(payload)
    decoded = decode_pixels(payload + b"\xff" * 8, lead, DEV)  # alignment slack after the image is ignored
    assert decoded.dtype == dtype and decoded.shape == (5, 7)
    np.testing.assert_array_equal(decoded, pixels)


def test_leader_and_trailer_fields() -> None:
    lead = parse_leader(leader(12, MONO16, 640, 480, timestamp=123456789), DEV)
    assert (lead.block_id, lead.timestamp, lead.size_x, lead.size_y, lead.pixel_format_name) == (
        12, 123456789, 640, 480, "Mono16")
    trail = parse_trailer(trailer(12, 640 * 480 * 2, 480), DEV)
    assert (trail.block_id, trail.status, trail.valid_payload_size, trail.size_y) == (12, 0, 614400, 480)
    assert check_block(lead, trail, 614400, 614400, DEV) == 614400


@pytest.mark.parametrize("lead_bytes,trail_bytes,received,limit,match", [
    (leader(1, MONO8, 4, 2), trailer(2, 8, 2), 8, 8, "does not match"),
    (leader(1, MONO8, 4, 2), trailer(1, 8, 2, status=0x8FFF), 8, 8, "status"),
    (leader(1, MONO8, 4, 2), trailer(1, 8, 2), 7, 8, "received 7"),
    (leader(1, MONO8, 4, 2), trailer(1, 6, 2), 8, 8, "trailer reports"),
    (leader(1, MONO16, 4, 2), trailer(1, 16, 2), 16, 8, "configured payload"),
])
def test_check_block_mismatches(lead_bytes: bytes, trail_bytes: bytes, received: int, limit: int, match: str) -> None:
    with pytest.raises(ProtocolError, match=match):
        check_block(parse_leader(lead_bytes, DEV), parse_trailer(trail_bytes, DEV), received, limit, DEV)


@pytest.mark.parametrize("data", [leader(1, MONO8, 4, 2, magic=0x11111111), leader(1, MONO8, 4, 2)[:51],
                                  leader(1, MONO8, 4, 2, payload_type=0x4000)])
def test_bad_leaders(data: bytes) -> None:
    with pytest.raises(ProtocolError):
        parse_leader(data, DEV)


def block_transfers(block_id: int, pixels: np.ndarray, sizes: bs.TransferSizes, fmt: int = MONO8) -> list[bytes]:
    """Split one block as the device does: leader, count x size, final1, final2 (last one short), trailer."""
    payload = image_payload(pixels, 0)
    out = [leader(block_id, fmt, pixels.shape[1], pixels.shape[0])]
    plan = [sizes.payload_size] * sizes.payload_count + [s for s in (sizes.final1_size, sizes.final2_size) if s]
    position = 0
    for size in plan:
        out.append(payload[position:position + size])
        position += size
    return out + [trailer(block_id, len(payload), pixels.shape[0])]


def assembler_for(pixels: np.ndarray) -> tuple[BlockAssembler, bs.TransferSizes]:
    payload = pixels.size
    sizes = bs.compute_transfer_sizes(payload, 52, 32, 16, 64)
    return BlockAssembler(sizes, payload, DEV), sizes


def feed_all(assembler: BlockAssembler, transfers: list[bytes]) -> list[AssembledBlock | DiscardedBlock]:
    outcomes = []
    for transfer in transfers:
        assert len(transfer) <= assembler.next_read_size()  # the host's buffer always fits the transfer
        outcome = assembler.feed(transfer)
        if outcome is not None:
            outcomes.append(outcome)
    return outcomes


def test_assembler_good_blocks_and_resync_after_corruption() -> None:
    rng = np.random.default_rng(1)
    images = [rng.integers(0, 256, size=(9, 13)).astype(np.uint8) for _ in range(4)]
    assembler, sizes = assembler_for(images[0])
    good0 = block_transfers(0, images[0], sizes)
    bad_leader = block_transfers(1, images[1], sizes)
    bad_leader[0] = leader(1, MONO8, 13, 9, magic=0xDEADBEEF)
    bad_trailer = block_transfers(2, images[2], sizes)
    bad_trailer[-1] = trailer(7, images[2].size, 9)  # wrong block id
    good3 = block_transfers(3, images[3], sizes)
    outcomes = feed_all(assembler, good0 + bad_leader + bad_trailer + good3)
    kinds = [(type(o).__name__, o.leader.block_id if isinstance(o, AssembledBlock) else o.block_id) for o in outcomes]
    # the corrupt leader's run of transfers counts once (no block id); the bad trailer discards block 2
    assert kinds == [("AssembledBlock", 0), ("DiscardedBlock", None), ("DiscardedBlock", 2), ("AssembledBlock", 3)]
    np.testing.assert_array_equal(outcomes[0].pixels, images[0])  # type: ignore[union-attr]
    np.testing.assert_array_equal(outcomes[-1].pixels, images[3])  # type: ignore[union-attr]


def test_assembler_short_payload_and_missing_trailer() -> None:
    rng = np.random.default_rng(2)
    images = [rng.integers(0, 256, size=(9, 13)).astype(np.uint8) for _ in range(3)]
    assembler, sizes = assembler_for(images[0])
    short = block_transfers(0, images[0], sizes)
    short[1] = short[1][:10]  # partial transfer: the trailer then reports more than was received
    no_trailer = block_transfers(1, images[1], sizes)[:-1]
    outcomes = feed_all(assembler, short + no_trailer + block_transfers(2, images[2], sizes))
    assert [type(o).__name__ for o in outcomes] == ["DiscardedBlock", "DiscardedBlock", "AssembledBlock"]
    assert "received" in outcomes[0].reason and "no trailer" in outcomes[1].reason  # type: ignore[union-attr]


def test_assembler_abort_mid_block() -> None:
    image = np.arange(117, dtype=np.uint8).reshape(9, 13)
    assembler, sizes = assembler_for(image)
    transfers = block_transfers(5, image, sizes)
    assert feed_all(assembler, transfers[:2]) == [] and assembler.in_block
    aborted = assembler.abort("stall")
    assert isinstance(aborted, DiscardedBlock) and aborted.block_id == 5
    # the rest of the interrupted block is skipped silently (already counted), the next block is good
    outcomes = feed_all(assembler, transfers[2:] + block_transfers(6, image, sizes))
    assert [type(o).__name__ for o in outcomes] == ["AssembledBlock"]
    assert outcomes[0].leader.block_id == 6  # type: ignore[union-attr]


# ------------------------------------------------------------------------------ fuzzing
def only_protocol_errors(call) -> None:  # type: ignore[no-untyped-def]
    try:
        call()
    except ProtocolError:
        pass


@fuzz_settings(300)
@given(data=st.binary(max_size=600))
def test_fuzz_byte_parsers(data: bytes) -> None:
    for parser in (gencp.parse_acknowledge, bs.decode_abrm, bs.decode_sbrm, bs.decode_sirm, bs.decode_manifest_count,
                   bs.decode_manifest_entry, parse_leader, parse_trailer):
        only_protocol_errors(lambda: parser(data, DEV))  # noqa: B023 - called at once


@fuzz_settings(100)
@given(header=st.binary(min_size=52, max_size=52), payload=st.binary(max_size=300))
def test_fuzz_decode_pixels(header: bytes, payload: bytes) -> None:
    forged = struct.pack("<I", 0x4C563355) + header[4:6] + struct.pack("<H", 52) + header[8:]
    try:
        lead = parse_leader(forged, DEV)
    except ProtocolError:
        return
    only_protocol_errors(lambda: decode_pixels(payload, lead, DEV))


@fuzz_settings(100)
@given(transfers=st.lists(st.one_of(st.binary(max_size=80), st.sampled_from([
    leader(1, MONO8, 13, 9), leader(2, MONO16, 4, 4), trailer(1, 117, 9), trailer(2, 32, 4)])), max_size=30))
def test_fuzz_assembler(transfers: list[bytes]) -> None:
    assembler, _ = assembler_for(np.zeros((9, 13), np.uint8))
    for transfer in transfers:
        outcome = assembler.feed(transfer)
        assert outcome is None or isinstance(outcome, (AssembledBlock, DiscardedBlock))
        assert assembler.next_read_size() >= 52

