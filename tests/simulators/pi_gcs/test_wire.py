"""Every wire rule of GCS 2.0, checked through a plain socket against the simulated controller."""

from __future__ import annotations

import pytest

from wavestack.simulators.pi_gcs import HEXAPOD_AXES, HexapodSimSettings


def test_several_commands_in_one_packet_are_answered_in_order(serve, connect) -> None:
    link = connect(serve())
    link.send(b"CSV?\nMOV X 1\nERR?\n*IDN?\nERR?\n")
    assert link.reply() == b"2.0\n"
    assert link.reply() == b"0\n"
    assert link.reply().decode().startswith("Physik Instrumente")
    assert link.reply() == b"0\n"


def test_a_command_split_over_packets_is_assembled(serve, connect) -> None:
    link = connect(serve())
    for piece in (b"PO", b"S? ", b"X Y", b"\n"):
        link.send(piece)
    assert link.reply() == b"X=0.000000000 \nY=0.000000000\n"
    for byte in b"CSV?\n":  # one byte per packet
        link.send(bytes([byte]))
    assert link.reply() == b"2.0\n"


@pytest.mark.parametrize("query", ["POS?", "SAI?", "SAI? ALL", "ONT?", "TMN?", "TMX?", "SVO?", "FRF?", "MOV?",
                                   "SPI?", "HLP?"])
def test_every_line_of_a_multi_line_answer_but_the_last_ends_with_a_space(serve, connect, query: str) -> None:
    link = connect(serve())
    answer = link.ask(query)
    lines = answer.split("\n")
    assert lines[-1] == ""  # the answer ends with LF
    body = lines[:-1]
    assert len(body) >= 2
    assert all(line.endswith(" ") for line in body[:-1])
    assert not body[-1].endswith(" ")


def test_axis_queries_answer_every_axis_in_controller_order(serve, connect) -> None:
    link = connect(serve())
    assert link.ask("SAI?") == " \n".join(HEXAPOD_AXES) + "\n"
    assert list(link.values("POS?")) == list(HEXAPOD_AXES)
    assert list(link.values("ONT? W X")) == ["W", "X"]


def test_ready_byte_answers_b1_then_lf_at_once(serve, connect) -> None:
    link = connect(serve())
    link.send(b"\x07")  # no LF: answered at once
    assert link.reply() == b"\xb1\n"


def test_motion_status_byte_is_a_hex_bit_mask_of_the_moving_axes(serve, connect, clock) -> None:
    link = connect(serve(clock=clock))
    link.send(b"\x05")
    assert link.reply() == b"0\n"
    link.send(b"MOV Y 1 W 2\n")
    link.send(b"\x05")
    assert int(link.reply(), 16) == (1 << 1) | (1 << 5)  # Y is axis 2 (bit 1), W axis 6 (bit 5)
    clock.advance(60.0)
    link.send(b"\x05")
    assert link.reply() == b"0\n"


def test_a_single_byte_command_inside_a_line_is_answered_first_and_leaves_the_line_whole(serve, connect) -> None:
    link = connect(serve())
    link.send(b"POS? ")
    link.send(b"\x05")
    assert link.reply() == b"0\n"
    link.send(b"X\n")
    assert link.reply() == b"X=0.000000000\n"


def test_stop_all_byte_stops_the_platform_answers_nothing_and_sets_error_10(serve, connect, clock) -> None:
    simulator = serve(clock=clock)
    link = connect(simulator)
    link.send(b"MOV X 10\n")
    assert link.error() == 0  # the move was taken (and the server has read it) before time moves
    clock.advance(1.0)  # 2 mm/s: at X = 2
    link.send(b"\x18")
    assert link.ask("CSV?") == "2.0\n"  # nothing answered the #24 before this
    assert simulator.pose["X"] == pytest.approx(2.0)
    clock.advance(60.0)
    assert float(link.values("POS? X")["X"]) == pytest.approx(2.0)
    assert link.values("ONT? X") == {"X": "1"}
    assert link.error() == 10
    assert link.error() == 0  # ERR? cleared it


@pytest.mark.parametrize("command", ["HLT", "HLT X", "STP"])
def test_halt_and_stop_set_error_10(serve, connect, command: str) -> None:
    link = connect(serve())
    link.send(command.encode() + b"\n")
    assert link.error() == 10


def test_err_returns_the_last_error_and_clears_it(serve, connect) -> None:
    link = connect(serve())
    link.send(b"FOO\nMOV X 999\n")
    assert link.error() == 7  # the last one: only the last error is kept
    assert link.error() == 0


def test_csv_answers_the_gcs_syntax_version(serve, connect) -> None:
    assert connect(serve()).ask("CSV?") == "2.0\n"


@pytest.mark.parametrize(("command", "code"), [
    ("FOO", 2), ("MOV? Q", 15), ("MOV Q 1", 15), ("MOV X 99", 7), ("MOV X -99", 7), ("MOV X", 1),
    ("MOV X abc", 1), ("MOV X nan", 1), ("MOV X 1 X 2", 22), ("CSV? X", 24), ("VLS 0", 8), ("VLS 1e9", 8),
    ("SVO X 2", 1), ("SPI Q 1", 15), ("POS? x", 15), ("MOV X 1_0", 1), ("MOV X 0x1", 1), ("MOV X 1e999", 1),
])
def test_refused_commands_set_pis_error_code_and_change_nothing(serve, connect, command: str, code: int) -> None:
    simulator = serve()
    link = connect(simulator)
    before = simulator.controller.targets
    link.send(command.encode() + b"\n")
    assert link.error() == code
    assert simulator.controller.targets == before


def test_a_failing_query_sends_no_answer(serve, connect) -> None:
    link = connect(serve())
    link.send(b"POS? Q\nCSV?\n")
    assert link.reply() == b"2.0\n"  # the first answer is CSV?'s: POS? Q said nothing
    assert link.error() == 15


def test_a_move_with_servo_off_or_unreferenced_is_refused_with_5(serve, connect) -> None:
    link = connect(serve())
    link.send(b"SVO Z 0\nMOV Z 1\n")
    assert link.error() == 5
    assert link.values("SVO?")["Z"] == "0"
    link.send(b"MOV X 1\n")  # other axes still move
    assert link.error() == 0
    unreferenced = connect(serve(HexapodSimSettings(referenced=False)))
    unreferenced.send(b"MOV X 1\n")
    assert unreferenced.error() == 5


def test_the_mnemonic_is_case_insensitive_and_crlf_is_tolerated(serve, connect) -> None:
    link = connect(serve())
    assert link.ask("csv?") == "2.0\n"
    link.send(b"pos? X\r\n")
    assert link.reply() == b"X=0.000000000\n"


def test_a_line_too_long_is_refused_with_3_never_run_cut_short(serve, connect) -> None:
    simulator = serve()
    link = connect(simulator)
    link.send(b"MOV X 1" + b" " * 5000 + b"\n")
    assert link.error() == 3
    assert simulator.controller.targets["X"] == 0.0


def test_two_clients_share_one_controller(serve, connect) -> None:
    simulator = serve()
    first, second = connect(simulator), connect(simulator)
    first.send(b"FOO\n")
    assert second.error() == 2
    assert simulator.connections == 2
