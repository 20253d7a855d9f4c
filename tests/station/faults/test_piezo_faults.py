"""Piezo (MDT693B) faults against the live phase-shifting station, through the simulated controller's switches.

Each test asserts what :func:`check_fault_run` checks (survival, reasons, counters that add up
and only grow, no exception escaping a thread, no PLC watchdog trip while the fault lasts), and
that a piezo that went away is opened again: its next set comes from the reopened port, at the
calibration's bias and steps.
"""

from __future__ import annotations

import pytest
from station.faults.harness import check_fault_run, fault_config, run_fault


def _lost(run) -> list:
    return [r.result for r in run.records[run.injected_at:] if not r.result.valid]


@pytest.mark.parametrize("fault", ["garbage", "silent", "unplugged"])
def test_a_faulty_piezo_gives_invalid_results_then_valid_ones_again(station_factory, check_counts, thread_errors,
                                                                   fault) -> None:
    station, devices = station_factory(fault_config())
    piezo = devices.bench.piezo

    def clear() -> None:
        setattr(piezo.faults, fault, False)

    run = run_fault(station, devices, inject=lambda: setattr(piezo.faults, fault, True), clear=clear, hold_s=1.5)
    check_fault_run(run, check_counts, 5)
    lost = _lost(run)
    assert lost and all(r.reason.startswith("device: MDT693B") for r in lost), [r.reason for r in lost]
    assert devices.piezo.is_open
    # the steps after the fault: bias 20 V + 10 V/rad x (0, 90, ..., 360 deg)
    commanded = [c for c in piezo.commands[-40:] if c.startswith("xvoltage=")]
    assert commanded and all(0.0 <= float(c.split("=")[1]) <= 120.0 for c in commanded)


def test_split_replies_are_reassembled_and_every_result_stays_valid(station_factory, check_counts,
                                                                    thread_errors) -> None:
    station, devices = station_factory(fault_config())
    piezo = devices.bench.piezo

    def clear() -> None:
        piezo.faults.split_replies = False

    run = run_fault(station, devices, inject=lambda: setattr(piezo.faults, "split_replies", True), clear=clear,
                    hold_s=1.5)
    check_fault_run(run, check_counts, 5)
    assert all(r.result.valid for r in run.records[run.injected_at:]), \
        [r.result.reason for r in run.records[run.injected_at:]]
