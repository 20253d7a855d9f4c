"""Random bytes into the command parser never crash the controller and always leave it answering."""

from __future__ import annotations

import socket

from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.simulators.pi_gcs import GcsController, HexapodSimSettings, HexapodSimulator, LineAssembler

# Bytes a GCS host might plausibly send, mixed with anything: commands, axes, numbers, the
# single-byte commands, separators and line ends, so the fuzzer reaches the command handlers.
_WORDS = st.sampled_from([b"MOV", b"POS?", b"ONT?", b"SVO", b"FRF", b"SPI", b"SPI?", b"VLS", b"HLT", b"STP",
                          b"ERR?", b"SAI?", b"X", b"Y", b"W", b"R", b"T", b"1", b"-1e3", b"0.5", b"nan", b"0",
                          b" ", b"\n", b"\x05", b"\x07", b"\x18", b"\r", b"\t"])
_STREAMS = st.lists(st.one_of(_WORDS, st.binary(max_size=40)), max_size=40).map(b"".join)


def _within_limits(controller: GcsController) -> bool:
    settings = controller.settings
    return all(lo <= p <= hi for p, lo, hi in zip(controller.pose.values, settings.low_limits, settings.high_limits))


@fuzz_settings(300)
@given(stream=_STREAMS, cuts=st.lists(st.integers(min_value=0, max_value=2000), max_size=5))
def test_the_controller_survives_any_bytes_and_answers_well_formed(stream: bytes, cuts: list[int]) -> None:
    controller = GcsController(HexapodSimSettings())
    assembler = LineAssembler()
    bounds = sorted({0, len(stream), *(c for c in cuts if c < len(stream))})
    for start, end in zip(bounds, bounds[1:]):  # the same bytes, cut into arbitrary packets
        for event in assembler.feed(stream[start:end]):
            delivery = controller.handle(event)
            reply = b"".join(chunk for _, chunk in delivery.pieces)
            if reply:
                assert reply.endswith(b"\n")
                assert b"\n" not in reply[:-1].replace(b" \n", b"")  # inner LFs all follow a space
        assert _within_limits(controller)
    for event in assembler.feed(b"\nERR?\nCSV?\n"):
        last = controller.handle(event)
    assert last.pieces == ((0.0, b"2.0\n"),)


def test_the_server_survives_any_bytes_and_keeps_answering() -> None:
    with HexapodSimulator(HexapodSimSettings()) as simulator:
        @fuzz_settings(60)
        @given(stream=_STREAMS)
        def check(stream: bytes) -> None:
            with socket.create_connection(("127.0.0.1", simulator.port), timeout=5.0) as hostile:
                hostile.sendall(stream)
            with socket.create_connection(("127.0.0.1", simulator.port), timeout=5.0) as link:
                link.sendall(b"CSV?\n")
                answer = b""
                while not answer.endswith(b"\n"):
                    chunk = link.recv(64)
                    assert chunk, "the simulator closed a fresh connection"
                    answer += chunk
                assert answer == b"2.0\n"
            assert _within_limits(simulator.controller)

        check()
