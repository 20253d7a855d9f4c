"""GVCP and GVSP parsers: the simulator's packets parse back to their fields, anything else is a
ProtocolError, and the block assembler never releases an image with a hole in it."""

from __future__ import annotations

import random

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fuzz import fuzz_settings
from wavestack.drivers.errors import ProtocolError
from wavestack.drivers.gige import gvcp, gvsp
from wavestack.simulators.gige import protocol as device

DEV = "GigE test camera"
MONO12 = 0x01100005


@fuzz_settings(300)
@given(data=st.binary(max_size=300), request_id=st.integers(1, 0xFFFF))
def test_any_acknowledge_parses_or_raises_protocol_error(data: bytes, request_id: int) -> None:
    try:
        ack = gvcp.parse_ack(data, DEV, answer=gvcp.READREG_ACK, request_id=request_id)
    except ProtocolError as error:
        assert error.device == DEV
        return
    assert ack.ack_id == request_id


@fuzz_settings(200)
@given(status=st.integers(0, 0xFFFF), request_id=st.integers(1, 0xFFFF), words=st.lists(st.integers(0, 2**32 - 1),
                                                                                          max_size=8))
def test_the_devices_acknowledges_parse_back(status: int, request_id: int, words: list[int]) -> None:
    command = device.parse_command(gvcp.encode_readreg(request_id, [4 * i for i in range(max(1, len(words)))]))
    assert command is not None and command.code == gvcp.READREG_CMD and command.request_id == request_id
    payload = b"".join(w.to_bytes(4, "big") for w in words)
    ack = gvcp.parse_ack(device.acknowledge(status, command, payload), DEV, answer=gvcp.READREG_ACK,
                         request_id=request_id)
    assert (ack.status, ack.payload) == (status, payload)
    with pytest.raises(gvcp.WrongAck):
        gvcp.parse_ack(device.acknowledge(status, command, payload, ack_id=request_id % 0xFFFF + 1), DEV,
                       answer=gvcp.READREG_ACK, request_id=request_id)


def test_discovery_and_first_url() -> None:
    payload = device.discovery_payload(version=(2, 0), mac=0x0200_5E57_AC01, ip=0x7F000001, manufacturer="wavestack",
                                       model="WaveCam", device_version="1.0", serial="SN42", user_name="lab")
    info = gvcp.parse_discovery(payload, DEV)
    assert (info.address, info.mac, info.model, info.serial, info.user_name) == (
        "127.0.0.1", "02:00:5e:57:ac:01", "WaveCam", "SN42", "lab")
    url = gvcp.parse_first_url(b"Local:cam.zip;10000;F8C1A\0\0", DEV)
    assert (url.name, url.address, url.length, url.zipped) == ("cam.zip", 0x10000, 0xF8C1A, True)
    for bad in (b"http://vendor.example/cam.xml", b"Local:cam.xml;zz;10", b"Local:cam.xml;10", b"Local:a;0;0"):
        with pytest.raises(ProtocolError):
            gvcp.parse_first_url(bad, DEV)


@fuzz_settings(300)
@given(data=st.binary(max_size=120))
def test_any_datagram_parses_or_raises_protocol_error(data: bytes) -> None:
    try:
        packet = gvsp.parse_packet(data, DEV)
    except ProtocolError:
        return
    if packet.packet_format == gvsp.FORMAT_LEADER:
        try:
            gvsp.parse_leader(packet.body, DEV, 1 << 20)
        except ProtocolError:
            pass


def block(block_id: int, pixels: np.ndarray, data_size: int) -> list[bytes]:
    return device.block_packets(block_id, 123, MONO12, pixels.shape[1], pixels.shape[0],
                                pixels.astype("<u2").tobytes(), data_size)


@fuzz_settings(200)
@given(seed=st.integers(0, 2**32 - 1), loss=st.floats(0, 0.5), width=st.integers(1, 40), height=st.integers(1, 20))
def test_the_assembler_releases_only_whole_images_whatever_the_order_and_loss(seed: int, loss: float, width: int,
                                                                              height: int) -> None:
    rng = random.Random(seed)
    pixels = np.arange(width * height, dtype=np.uint16).reshape(height, width) % 4096
    packets = block(7, pixels, 64)
    arrived = [pk for pk in packets if rng.random() >= loss]
    rng.shuffle(arrived)
    assembler = gvsp.BlockAssembler(DEV, 64, 1 << 20)
    images, asked = [], []
    for now, datagram in enumerate(arrived):
        progress = assembler.feed(gvsp.parse_packet(datagram, DEV), now * 0.001)
        images += progress.images
        asked += progress.resend
    progress = assembler.tick(1.0)  # past give-up: what is incomplete is dropped, never released
    images += progress.images
    if len(arrived) == len(packets):
        assert len(images) == 1 and np.array_equal(images[0].pixels, pixels)
    else:
        assert images == [] and (progress.dropped or asked or not arrived)
    for image in images:
        assert np.array_equal(image.pixels, pixels)


def test_resent_packets_complete_a_block_and_late_duplicates_are_ignored() -> None:
    pixels = np.arange(200, dtype=np.uint16).reshape(10, 20)
    packets = block(3, pixels, 100)
    assembler = gvsp.BlockAssembler(DEV, 100, 1 << 20)
    missing = packets[2]
    for datagram in packets[:2] + packets[3:]:
        progress = assembler.feed(gvsp.parse_packet(datagram, DEV), 0.0)
    assert progress.resend == [(3, 2, 2)] and progress.images == []
    progress = assembler.feed(gvsp.parse_packet(missing, DEV), 0.01)
    assert len(progress.images) == 1 and np.array_equal(progress.images[0].pixels, pixels)
    assert assembler.feed(gvsp.parse_packet(missing, DEV), 0.02).images == []  # a second copy: ignored
