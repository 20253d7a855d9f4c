"""Hostile peers of the simulated polishing PLC (Modbus/TCP on loopback): one owner per connection.

A second Modbus client, as any program on the network can be, against the station's link: it may
read, and re-arm a tripped watchdog (the operator's register), nothing else. Raw pymodbus clients
stand for the stranger; every wait is bounded.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from pymodbus.client import ModbusTcpClient
from pymodbus.pdu import ExceptionResponse

from wavestack.drivers.plc import (JobFile, JobLimits, JobReason, JobRejected, LinkTiming, PolishingLink,
                                   RegisterMap, WriteRefused, write_job_file)
from wavestack.simulators.plc import (MachineSimSettings, PlcSimLayout, PlcSimulator, PolishingMachine,
                                      PolishingStation, WatchdogState)

TIMING = LinkTiming(io_timeout_s=0.5, reconnect_initial_s=0.02, reconnect_max_s=0.2, command_retries=2,
                    heartbeat_echo_max_lag=2)
LIMITS = JobLimits(500_000, 10_000.0, 20.0, 100.0, (-5.0, 5.0), (-5.0, 5.0))
WAIT_S = 10.0  # bounds a wait for a state; never a timing assertion
MAP = dict(unit_id=1, self_check_register=0, self_check_value=12345.678, heartbeat_register=10, rearm_register=11,
           owner_register=12, status_register=20, command_block=(100, 10), output_block=(200, 10), job_register=300,
           machine_register=320)


def layout(watchdog_timeout_s: float) -> PlcSimLayout:
    values = {k: v for k, v in MAP.items()}
    return PlcSimLayout(**values, self_check_word_order="CDAB", command_word_order="CDAB",  # type: ignore[arg-type]
                        output_word_order="CDAB", watchdog_timeout_s=watchdog_timeout_s)


def register_map() -> RegisterMap:
    return RegisterMap.build(word_order="CDAB", **MAP)  # type: ignore[arg-type]


@contextmanager
def station(folder: Path, watchdog_timeout_s: float = 1.0) -> Iterator[tuple[PlcSimulator, PolishingLink]]:
    machine = PolishingMachine(MachineSimSettings(folder, time_scale=1.0, travel_x_mm=(-4.0, 4.0),
                                                  travel_y_mm=(-4.0, 4.0), max_dwell_per_point_s=10.0))
    with PlcSimulator(layout(watchdog_timeout_s), PolishingStation((0.0,) * 4), machine=machine) as sim:
        with PolishingLink("127.0.0.1", sim.port, register_map(), TIMING, job_limits=LIMITS) as link:
            link.connect(timeout_s=2.0)
            link.self_check(timeout_s=1.0)
            link.heartbeat(timeout_s=1.0)
            yield sim, link


@contextmanager
def stranger(sim: PlcSimulator) -> Iterator[ModbusTcpClient]:
    client = ModbusTcpClient("127.0.0.1", port=sim.port, timeout=1.0, retries=0)
    assert client.connect()
    try:
        yield client
    finally:
        client.close()


def refused_code(reply: object) -> int | None:
    return int(reply.exception_code) if isinstance(reply, ExceptionResponse) else None


def wait_for(condition: Callable[[], bool], beat: PolishingLink | None = None) -> bool:
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        if beat is not None:
            beat.heartbeat(timeout_s=1.0)
        if condition():
            return True
        time.sleep(0.02)
    return condition()


def test_a_second_client_reads_but_cannot_beat_command_or_drive_jobs(tmp_path: Path) -> None:
    with station(tmp_path, watchdog_timeout_s=60.0) as (sim, link):
        with stranger(sim) as other:
            assert not other.read_holding_registers(20, count=3, device_id=1).isError()  # reading is open
            beat = sim.heartbeat_value
            assert refused_code(other.write_register(10, beat + 7, device_id=1)) == 1  # the heartbeat
            assert refused_code(other.write_registers(100, [99, 1] + [0] * 8, device_id=1)) == 1  # a command
            assert refused_code(other.write_registers(300, [1, 65535, 0, 0, 1, 0, 0, 0], device_id=1)) == 1  # a load
            assert refused_code(other.write_registers(300, [3, 1, 0, 0, 0, 0, 0, 0], device_id=1)) == 1  # an abort
            assert refused_code(other.write_registers(12, [1, 2, 3, 4], device_id=1)) == 1  # another token
            assert refused_code(other.write_register(11, 0, device_id=1)) is None  # the operator's register
        assert sim.heartbeat_value == beat and sim.accepted_commands == [] and sim.last_accepted_id == 0
        assert link.heartbeat(timeout_s=1.0).ready  # the station's link goes on


def test_a_dead_station_trips_its_watchdog_whoever_beats_and_its_job_stops(tmp_path: Path) -> None:
    with station(tmp_path, watchdog_timeout_s=1.0) as (sim, link):
        n = 400
        job = JobFile(1, np.linspace(-2, 2, n), np.zeros(n), np.full(n, 0.5), np.full(n, 20.0), 0.1,
                      {"kind": "gaussian"}, {"pixels": 1})
        link.load_job(write_job_file(tmp_path, job), 1)
        link.start_job(1)
        link.close()  # the station dies; its connection goes with it
        with stranger(sim) as other:
            beats = 0
            deadline = time.monotonic() + 3.0
            while time.monotonic() < deadline and sim.watchdog_state is not WatchdogState.TRIPPED:
                other.write_register(10, 1000 + beats, device_id=1)  # feeding the watchdog, as fast as it can
                beats += 1
                time.sleep(0.05)
            assert sim.watchdog_state is WatchdogState.TRIPPED
        assert sim.machine is not None and wait_for(lambda: sim.machine.snapshot().state.name == "ABORTED")
        assert sim.machine.snapshot().reason.name == "WATCHDOG"


def test_the_station_keeps_its_place_across_a_reconnect_and_a_plc_restart(tmp_path: Path) -> None:
    with station(tmp_path, watchdog_timeout_s=1.0) as (sim, link):
        link.close()
        assert link.heartbeat(timeout_s=1.0).ready  # a new connection: the same token takes the place back
        sim.restart(downtime_s=0.2)
        assert wait_for(lambda: _beats(link))
        assert sim.watchdog_trips == 0 and sim.program.owner_connection is not None


def _beats(link: PolishingLink) -> bool:
    try:
        return link.heartbeat(timeout_s=0.3).ready
    except Exception:  # noqa: BLE001 - refused or backing off while the server is down
        return False


def test_after_a_trip_the_operator_rearms_and_the_station_claims_again(tmp_path: Path) -> None:
    with station(tmp_path, watchdog_timeout_s=0.5) as (sim, link):
        assert wait_for(lambda: sim.watchdog_state is WatchdogState.TRIPPED)
        assert sim.program.owner_connection is None  # the trip ended the ownership
        monitor = PolishingLink("127.0.0.1", sim.port, register_map(), TIMING, monitor=True)
        with monitor:
            with pytest.raises(WriteRefused, match="re-arm register only"):
                monitor.write_registers(10, [5], timeout_s=1.0)  # before the wire: the heartbeat is the station's
            monitor.rearm(timeout_s=1.0)
        assert link.heartbeat(timeout_s=1.0).ready  # refused once (nobody owns it), claimed, beaten
        assert sim.watchdog_state is WatchdogState.RUNNING


class RoundTrips:
    """A second client timing status reads on loopback while something else happens; the slowest, s."""

    def __init__(self, sim: PlcSimulator) -> None:
        self._sim, self._stop, self.slowest, self.reads = sim, threading.Event(), 0.0, 0
        self._thread = threading.Thread(target=self._run)

    def __enter__(self) -> RoundTrips:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(WAIT_S)

    def _run(self) -> None:
        with stranger(self._sim) as client:
            client.comm_params.timeout_connect = 10.0  # a frozen PLC shows as a slow read, not a lost one
            while not self._stop.is_set():
                start = time.monotonic()
                client.read_holding_registers(20, count=3, device_id=1)
                self.slowest = max(self.slowest, time.monotonic() - start)
                self.reads += 1
                time.sleep(0.01)


def test_a_large_job_loads_in_the_background_and_the_plc_keeps_answering(tmp_path: Path) -> None:
    # issue 29, finding 3: the file was read and parsed in the Modbus event loop (a 500,000-point job
    # froze the PLC for 2.2-3.4 s and tripped the watchdog of the station that sent it)
    n = 300_000
    side = np.linspace(-3.0, 3.0, n)
    job = JobFile(1, side, np.zeros(n), np.full(n, 0.01), np.full(n, 50.0), 0.1, {"kind": "gaussian"},
                  {"pixels": 1})
    receipt = write_job_file(tmp_path, job)
    with station(tmp_path, watchdog_timeout_s=1.0) as (sim, link):
        with RoundTrips(sim) as trips:
            stop = threading.Event()
            beater = threading.Thread(target=_beat_until, args=(link, stop))
            beater.start()
            try:
                status = link.load_job(receipt, 1, timeout_s=2.0)
            finally:
                stop.set()
                beater.join(WAIT_S)
        assert status.state.name == "LOADED" and status.point_count == n
        assert sim.watchdog_trips == 0
        # a read that waited on the whole load would take the seconds the check takes; 0.5 s is
        # far above a loopback round trip on a loaded machine and far below a 300,000-point check
        assert trips.reads > 10 and trips.slowest < 0.5


def _beat_until(link: PolishingLink, stop: threading.Event) -> None:
    while not stop.wait(0.1):
        link.heartbeat(timeout_s=1.0)


def test_a_fifo_named_as_a_job_is_refused_without_waiting_on_it(tmp_path: Path) -> None:
    job = JobFile(1, np.zeros(2), np.zeros(2), np.ones(2), np.full(2, 10.0), 0.1, {"kind": "gaussian"}, {})
    (tmp_path / "elsewhere").mkdir()
    receipt = write_job_file(tmp_path / "elsewhere", job)  # its receipt; the job folder holds a FIFO by that name
    os.mkfifo(tmp_path / receipt.path.name)
    unblock = threading.Timer(5.0, _open_for_writing, args=(tmp_path / receipt.path.name,))
    unblock.start()  # the old reader waited on the FIFO until a writer came: it comes after 5 s
    try:
        with station(tmp_path, watchdog_timeout_s=60.0) as (sim, link):
            with RoundTrips(sim) as trips:
                with pytest.raises(JobRejected) as refused:
                    link.load_job(receipt, 1, timeout_s=2.0)
            assert refused.value.status.reason is JobReason.FILE_MISSING
            assert "not a regular file" in sim.machine.last_refusal
            assert trips.slowest < 0.5
    finally:
        unblock.cancel()
        unblock.join()


def _open_for_writing(path: Path) -> None:
    try:
        descriptor = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
    except OSError:  # nobody reads it (the new reader never opened it for long): nothing to unblock
        return
    os.close(descriptor)


def test_silent_strangers_cannot_fill_the_plc_but_busy_ones_keep_their_places(tmp_path: Path) -> None:
    machine = PolishingMachine(MachineSimSettings(tmp_path))
    with PlcSimulator(layout(60.0), PolishingStation((0.0,) * 4), machine=machine, max_connections=3,
                      quiet_s=1.0) as sim:
        with stranger(sim) as one, stranger(sim) as two, stranger(sim) as three:
            for peer in (one, two, three):  # three busy peers fill the cap: a fourth is closed on arrival
                assert not peer.read_holding_registers(20, count=1, device_id=1).isError()
            with stranger(sim):
                assert wait_for(lambda: sim.connections_refused == 1)
            time.sleep(1.2)  # now all three are quiet: the station's link takes the place of the quietest
            with PolishingLink("127.0.0.1", sim.port, register_map(), TIMING, job_limits=LIMITS) as link:
                link.connect(timeout_s=2.0)
                assert link.heartbeat(timeout_s=1.0).ready
                owner = sim.program.owner_connection
                time.sleep(1.2)  # the station is the quiet one now, but it owns the PLC: it keeps its place
                for peer in (two, three):
                    assert not peer.read_holding_registers(20, count=1, device_id=1).isError()
                with stranger(sim):
                    assert wait_for(lambda: sim.connections_refused == 2)
                assert link.heartbeat(timeout_s=1.0).ready
                assert sim.program.owner_connection == owner is not None  # the same connection
