"""The PLC output stage on the simulated PLC: commit on acknowledge, keep-alive, re-arm by an operator."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace

import numpy as np
import pytest

from wavestack.config import OutputSettings, load_plc_config
from wavestack.drivers.plc import PolishingLink
from wavestack.simulated import plc_layout, polishing_station
from wavestack.simulators.plc import PlcSimulator, WatchdogState
from wavestack.station.output_state import OutputMode
from wavestack.station.outputs import PlcOutput

SETTINGS = OutputSettings(first_term=1, gain=1.0, surface_factor=1.0, max_removal_nm=200.0, max_step_nm=50.0)
WAVELENGTH_NM = 100.0  # 1 wave of wavefront = 100 nm of removal with gain 1, surface factor 1


@contextmanager
def _output(watchdog_timeout_s: float = 60.0, **kwargs: float) -> Iterator[tuple[PlcSimulator, PlcOutput]]:
    config = load_plc_config(None)
    layout = replace(plc_layout(config), watchdog_timeout_s=watchdog_timeout_s)
    with PlcSimulator(layout, polishing_station(config)) as sim, \
            PolishingLink("127.0.0.1", sim.port, config.link.register_map(), config.link.link_timing()) as link:
        link.connect(timeout_s=2.0)
        link.self_check(timeout_s=2.0)
        yield sim, PlcOutput(link, SETTINGS, config.link.n_terms, wavelength_nm=WAVELENGTH_NM, max_age_s=10.0,
                             timeout_s=2.0, **kwargs)


def _publish(output: PlcOutput, waves: float):
    """A valid fresh result asking for ``waves * 100`` nm on every term."""
    now = time.time()
    output.heartbeat()
    return output.publish(np.full(15, waves), valid=True, measured_at_s=now, now_s=now, reason=None)


def _accepted(sim: PlcSimulator) -> list[float]:
    return [values[0] for values in sim.program.accepted_removals]


def test_a_refused_command_never_moves_the_base_of_the_rate_limit() -> None:
    """The issue's case: after an e-stop the PLC received 50 -> 150 nm against a 50 nm step limit."""
    with _output() as (sim, output):
        assert _publish(output, 1.5).sent  # 0 -> 50
        sim.faults.estop = True
        held = _publish(output, 1.5)
        assert not held.sent and held.status == "HELD|ESTOP" and "emergency stop" in held.reason
        sim.faults.estop = False
        assert _publish(output, 1.5).sent and _publish(output, 1.5).sent
        assert _accepted(sim) == [50.0, 100.0, 150.0]  # never 50 -> 150


def test_a_lost_reply_gets_a_new_id_and_the_next_step_counts_from_what_the_plc_took() -> None:
    with _output() as (sim, output):
        assert _publish(output, 1.0).sent
        sim.faults.drop_replies(3, function_code=16)  # the PLC takes the command, the host never hears so
        lost = _publish(output, 2.0)
        assert not lost.sent and lost.status.endswith("NOT_SENT") and lost.reason.startswith("PLC: ")
        assert _accepted(sim) == [50.0, 100.0]
        again = _publish(output, 3.0)  # no ValueError: a new id, from the 100 the machine holds
        assert again.sent and again.command_id == 3 and _accepted(sim) == [50.0, 100.0, 150.0]


def test_keep_alive_beats_only_when_due_and_never_commands() -> None:
    with _output(heartbeat_period_s=0.2) as (sim, output):
        assert _publish(output, 1.0).sent
        start = time.monotonic()
        assert output.keep_alive(start) is None  # the publish just beat
        beat = sim.heartbeat_value
        writes = sum(r.function_code == 16 for r in sim.requests)
        heartbeat = output.keep_alive(start + 0.25)
        assert heartbeat is not None and heartbeat.ok and sim.heartbeat_value == beat + 1
        assert sum(r.function_code == 16 for r in sim.requests) == writes
    with pytest.raises(ValueError, match="heartbeat_period_s"):
        with _output(heartbeat_period_s=0.0):
            pass


def test_after_a_trip_nothing_is_sent_until_an_operator_rearms_then_the_stage_restarts_from_the_machine() -> None:
    with _output(watchdog_timeout_s=0.5) as (sim, output):
        assert _publish(output, 1.0).sent and _publish(output, 1.0).sent  # the machine holds 100 nm
        deadline = time.monotonic() + 10.0
        while sim.watchdog_state is not WatchdogState.TRIPPED and time.monotonic() < deadline:
            time.sleep(0.05)  # the host stalls: no heartbeat
        for _ in range(3):
            held = _publish(output, 1.0)
            assert not held.sent and held.status == "HELD|TRIPPED" and "wavestack plc rearm" in held.reason
        assert output.state.mode is OutputMode.TRIPPED and sim.watchdog_trips == 1  # never re-armed by itself
        config = load_plc_config(None).link
        with PolishingLink("127.0.0.1", sim.port, config.register_map(), monitor=True) as operator:
            operator.rearm(timeout_s=2.0)
        sent = _publish(output, 1.0)
        assert sent.sent and sent.values_nm[0] == 50.0  # from the 0 the watchdog left, not from 100
        assert _accepted(sim) == [50.0, 100.0, 50.0]


def test_the_record_of_a_held_result_carries_the_output_state() -> None:
    with _output() as (sim, output):
        sim.faults.estop = True
        heartbeat = output.heartbeat()
        assert heartbeat.to_json() == {"heartbeat": True, "watchdog_tripped": False, "ready": False, "estop": True,
                                       "plc_state": "ESTOP"}
