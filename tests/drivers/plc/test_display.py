"""The result display block: its encoding, its place in the register map, and who may write it.

The driver writes it through the link that owns the simulated PLC; a third party (the PLC's HMI)
reads it with a plain pymodbus client and decodes it with pymodbus's own converter, so the test
does not trust the driver's codec to read what the driver's codec wrote.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st
from plc_panel import read_panel
from pymodbus.client import ModbusTcpClient

from wavestack.drivers import ProtocolError
from wavestack.drivers.plc import (LIMITING_QUANTITIES, LinkTiming, PlcRefused, PolishingLink, RegisterMap,
                                   ResultDisplay, SpecCode, WriteRefused, decode_display, encode_display,
                                   invalid_display, round_to_float32)
from wavestack.simulators.plc import PlcSimLayout, PlcSimulator, PolishingStation, WatchdogState

DISPLAY = 340
TIMING = LinkTiming(io_timeout_s=0.5, reconnect_initial_s=0.02, reconnect_max_s=0.2, command_retries=2,
                    heartbeat_echo_max_lag=2)
SHOWN = ResultDisplay(result_index=70_001, valid=True, residual_rms_nm=3.21, pvr_nm=45.6, spec=SpecCode.FAIL,
                      limiting="RSI")


def build(**overrides: Any) -> RegisterMap:
    values: dict[str, Any] = dict(unit_id=1, word_order="CDAB", self_check_register=0, self_check_value=12345.678,
                                  heartbeat_register=10, rearm_register=11, owner_register=12, status_register=20,
                                  command_block=(100, 10), output_block=(200, 10), display_register=DISPLAY)
    values.update(overrides)
    return RegisterMap.build(**values)


@contextmanager
def plc(watchdog_timeout_s: float = 60.0) -> Iterator[tuple[PlcSimulator, PolishingLink, ModbusTcpClient]]:
    """The simulated PLC, the station's owning link, and a third party's plain pymodbus client."""
    layout = PlcSimLayout(unit_id=1, self_check_register=0, self_check_value=12345.678, self_check_word_order="CDAB",
                          heartbeat_register=10, rearm_register=11, owner_register=12, status_register=20,
                          command_block=(100, 10), output_block=(200, 10), command_word_order="CDAB",
                          output_word_order="CDAB", watchdog_timeout_s=watchdog_timeout_s,
                          display_register=DISPLAY)
    with PlcSimulator(layout, PolishingStation((1.0, 2.0, 3.0, 4.0), noise_nm=0.0, seed=1)) as sim:
        with PolishingLink("127.0.0.1", sim.port, build(), TIMING) as link:
            link.connect(timeout_s=2.0)
            link.self_check(timeout_s=1.0)
            client = ModbusTcpClient("127.0.0.1", port=sim.port, timeout=1.0, retries=0)
            try:
                assert client.connect()
                yield sim, link, client
            finally:
                client.close()


# ----------------------------------------------------------------------------- the encoding (pure)
@fuzz_settings(200)
@given(index=st.integers(0, 2**31), valid=st.booleans(), rms=st.floats(0, 1e6), pvr=st.none() | st.floats(0, 1e6),
       verdict=st.sampled_from([(SpecCode.NO_SPEC, ""), (SpecCode.NOT_JUDGED, "")]
                               + [(code, name) for code in (SpecCode.PASS, SpecCode.FAIL)
                                  for name in LIMITING_QUANTITIES[1:]]),
       order=st.sampled_from(["ABCD", "CDAB", "BADC", "DCBA"]))
def test_the_block_round_trips_up_to_float32_and_the_counter_modulus(index: int, valid: bool, rms: float,
                                                                      pvr: float | None, verdict: tuple[SpecCode, str],
                                                                      order: str) -> None:
    display = ResultDisplay(index, valid, rms, pvr, *verdict)
    words = encode_display(display, order)  # type: ignore[arg-type]
    assert len(words) == 8 and all(0 <= w <= 0xFFFF for w in words)
    back = decode_display(words, order)  # type: ignore[arg-type]
    assert back.result_index == index % 65536 and back.valid == valid
    assert back.residual_rms_nm == (round_to_float32(rms) if valid else 0.0)  # an invalid result carries no figure
    assert back.pvr_nm == (None if pvr is None else round_to_float32(pvr))
    assert (back.spec, back.limiting) == verdict


def test_the_code_tables_are_the_documented_ones() -> None:
    # docs/instruments.md, "The result display block"
    assert [int(c) for c in SpecCode] == [0, 1, 2, 3]
    assert LIMITING_QUANTITIES == ("", "SAG", "IRR", "RSI", "RMSt", "RMSi", "RMSa")
    words = encode_display(SHOWN, "ABCD")
    assert words[0] == 70_001 - 65_536 and words[1] == 0b11 and words[6:] == [2, 3]
    assert encode_display(invalid_display(5, has_spec=True), "ABCD") == [5, 0, 0, 0, 0, 0, 3, 0]
    assert encode_display(invalid_display(5, has_spec=False), "ABCD") == [5, 0, 0, 0, 0, 0, 0, 0]


@pytest.mark.parametrize(("fields", "message"), [
    (dict(result_index=-1), "result_index"),
    (dict(residual_rms_nm=float("nan")), "residual_rms_nm"),
    (dict(pvr_nm=-1.0), "pvr_nm"),
    (dict(limiting="PV"), "limiting quantity 'PV'"),
    (dict(limiting=""), "FAIL verdict needs"),
    (dict(spec=SpecCode.NO_SPEC), "NO_SPEC verdict has no"),
])
def test_a_display_that_cannot_be_shown_is_refused(fields: dict[str, Any], message: str) -> None:
    values: dict[str, Any] = dict(result_index=1, valid=True, residual_rms_nm=1.0, pvr_nm=2.0, spec=SpecCode.FAIL,
                                  limiting="IRR")
    with pytest.raises(ValueError, match=message):
        ResultDisplay(**{**values, **fields})
    with pytest.raises(ValueError, match="limiting quantity code 9"):
        decode_display([0, 1, 0, 0, 0, 0, 2, 9], "ABCD")


# ----------------------------------------------------------------------------- the register map
def test_the_map_places_the_block_and_allows_only_a_whole_fc16_write() -> None:
    register_map = build()
    assert register_map.display is not None and (register_map.display.start, register_map.display.count) == (340, 8)
    assert register_map.check_write(DISPLAY, 8, 16) is register_map.display
    with pytest.raises(WriteRefused, match="written whole"):
        register_map.check_write(DISPLAY, 2, 16)
    with pytest.raises(WriteRefused, match="FC16 only"):
        register_map.check_write(DISPLAY, 1, 6)
    with pytest.raises(ValueError, match="overlaps"):
        build(display_register=205)
    with pytest.raises(ValueError, match="no display block"):
        build(display_register=None).encode_display(SHOWN)
    assert "| 340-347 | 8 |" in register_map.markdown_table()


# ----------------------------------------------------------------------------- over the wire
def test_the_owner_writes_it_and_a_third_party_reads_the_same_values() -> None:
    with plc() as (_, link, client):
        link.heartbeat(timeout_s=1.0)
        link.show_result(SHOWN, timeout_s=1.0)
        seen = read_panel(client, DISPLAY)
        assert seen["counter"] == SHOWN.result_index % 65536 and seen["flags"] == 0b11
        assert seen["rms_nm"] == pytest.approx(3.21, rel=1e-6) and seen["pvr_nm"] == pytest.approx(45.6, rel=1e-6)
        assert (seen["spec"], seen["limiting"]) == (2, LIMITING_QUANTITIES.index("RSI"))
        link.show_result(invalid_display(SHOWN.result_index + 1, has_spec=True), timeout_s=1.0)
        seen = read_panel(client, DISPLAY)
        assert seen["flags"] & 1 == 0 and seen["spec"] == int(SpecCode.NOT_JUDGED) and seen["rms_nm"] == 0.0


def test_a_monitor_or_a_stranger_cannot_write_it() -> None:
    with plc() as (sim, link, client):
        link.heartbeat(timeout_s=1.0)
        link.show_result(SHOWN, timeout_s=1.0)
        before = client.read_holding_registers(DISPLAY, count=8, device_id=1).registers
        with PolishingLink("127.0.0.1", sim.port, build(), TIMING, monitor=True) as monitor:
            monitor.connect(timeout_s=2.0)
            requests = sim.request_count
            with pytest.raises(ProtocolError, match="monitor link writes no display block"):
                monitor.show_result(invalid_display(1, has_spec=False), timeout_s=1.0)
            assert sim.request_count == requests  # refused before the wire
        # a stranger's raw FC16 of the whole block: exception 1 (not the owner), nothing changes
        reply = client.write_registers(DISPLAY, [1, 0, 0, 0, 0, 0, 0, 0], device_id=1)
        assert reply.isError() and reply.exception_code == 1
        assert client.read_holding_registers(DISPLAY, count=8, device_id=1).registers == before


def test_a_tripped_watchdog_clears_the_panel_and_refuses_the_write() -> None:
    with plc(watchdog_timeout_s=0.2) as (sim, link, client):
        link.heartbeat(timeout_s=1.0)
        link.show_result(SHOWN, timeout_s=1.0)
        assert read_panel(client, DISPLAY)["flags"] == 0b11
        deadline = time.monotonic() + 10.0  # a bound on the wait, never a timing assertion
        while sim.watchdog_state is not WatchdogState.TRIPPED and time.monotonic() < deadline:
            time.sleep(0.05)
        assert sim.watchdog_state is WatchdogState.TRIPPED
        with pytest.raises(PlcRefused) as refused:
            link.show_result(SHOWN, timeout_s=1.0)
        assert refused.value.exception_code == 4
        assert not client.write_register(11, 1, device_id=1).isError()  # the operator re-arms
        # a host that stopped must not leave its last verdict on the panel: zeros, "invalid, no spec"
        assert client.read_holding_registers(DISPLAY, count=8, device_id=1).registers == [0] * 8
