"""Fault switches: an error on the next command, dropped connections, split and truncated answers,
a stuck axis, a slow move."""

from __future__ import annotations

import socket

import pytest

from wavestack.simulators.pi_gcs import ReplyFault
from wavestack.simulators.pi_gcs.framing import deliver


def test_fail_next_refuses_the_next_command_with_the_code(serve, connect) -> None:
    simulator = serve()
    link = connect(simulator)
    simulator.faults.fail_next(5, command="MOV")
    assert link.ask("CSV?") == "2.0\n"  # another command is not hit
    link.send(b"MOV X 1\n")
    assert link.error() == 5
    assert simulator.controller.targets["X"] == 0.0  # not executed
    link.send(b"MOV X 1\n")
    assert link.error() == 0  # one shot only
    assert simulator.faults.pending == 0


def test_a_failed_query_answers_nothing(serve, connect) -> None:
    simulator = serve()
    link = connect(simulator)
    simulator.faults.fail_next(17)
    link.send(b"POS?\nCSV?\n")
    assert link.reply() == b"2.0\n"
    assert link.error() == 17


def test_a_dropped_connection_closes_before_the_command_runs(serve, connect) -> None:
    simulator = serve()
    link = connect(simulator)
    simulator.faults.drop_connection(command="MOV")
    link.send(b"MOV X 1\n")
    assert link.sock.recv(64) == b""  # closed by the controller
    assert simulator.controller.targets["X"] == 0.0
    assert connect(simulator).ask("CSV?") == "2.0\n"  # it still accepts new connections


def test_disconnect_clients_drops_every_connection(serve, connect) -> None:
    simulator = serve()
    links = [connect(simulator) for _ in range(2)]
    assert all(link.ask("CSV?") == "2.0\n" for link in links)
    simulator.disconnect_clients()
    assert [link.sock.recv(64) for link in links] == [b"", b""]


def test_a_split_answer_arrives_whole(serve, connect) -> None:
    simulator = serve()
    link = connect(simulator)
    whole = link.ask("POS?")
    simulator.faults.split_replies(pieces=3, gap_s=0.05, command="POS?")
    assert link.ask("POS?") == whole
    assert simulator.faults.pending == 0


def test_a_split_answer_is_cut_into_the_pieces_asked_for() -> None:
    reply = b"X=1 \nY=2\n"
    delivery = deliver(reply, ReplyFault("split", pieces=3, gap_s=0.05))
    assert b"".join(chunk for _, chunk in delivery.pieces) == reply
    assert [delay for delay, _ in delivery.pieces] == [0.0, 0.05, 0.05]
    assert all(chunk for _, chunk in delivery.pieces)
    assert deliver(reply, ReplyFault("truncate", keep_bytes=3)).pieces == ((0.0, b"X=1"),)


def test_a_truncated_answer_never_completes(serve, connect) -> None:
    simulator = serve()
    link = connect(simulator)
    simulator.faults.truncate_replies(keep_bytes=4, command="POS?")
    link.send(b"POS?\n")
    link.sock.settimeout(1.0)  # long enough for the kept bytes to arrive on a loaded machine
    received = b""
    with pytest.raises(socket.timeout):
        while True:
            received += link.sock.recv(4096)
    assert received == b"X=0."
    link.sock.settimeout(5.0)
    assert link.ask("CSV?") == "2.0\n"  # the controller still answers


def test_a_stuck_axis_never_reaches_its_target(serve, connect, clock) -> None:
    simulator = serve(clock=clock)
    link = connect(simulator)
    simulator.faults.stick_axis("Y")
    link.send(b"MOV X 1 Y 1\n")
    assert link.error() == 0
    clock.advance(1e6)
    assert link.values("ONT? X Y") == {"X": "1", "Y": "0"}
    assert simulator.pose["Y"] == 0.0
    link.send(b"\x05")
    assert int(link.reply(), 16) == 0b10  # Y still "moving"
    link.send(b"HLT\n")
    assert link.error() == 10
    assert link.values("ONT? Y") == {"Y": "1"}  # halted: its target is where it is


def test_a_slow_move_takes_the_factor_longer(serve, connect, clock) -> None:
    simulator = serve(clock=clock)
    link = connect(simulator)
    simulator.faults.slow_factor = 4.0
    link.send(b"MOV X 2\n")
    assert link.error() == 0
    clock.advance(1.0)  # 2 mm/s would have arrived; a quarter of the way at a fourth of the speed
    assert simulator.pose["X"] == pytest.approx(0.5)
    clock.advance(3.0)
    assert simulator.pose["X"] == 2.0
    with pytest.raises(ValueError):
        simulator.faults.slow_factor = 0.5
    simulator.faults.clear()
    assert simulator.faults.slow_factor == 1.0
