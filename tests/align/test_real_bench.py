"""A real alignment bench (``[align] simulated = false``): configuration, the fit without tilt, the remote bench.

The "remote" bench is :func:`~wavestack.cli.sim_align_bench.open_remote_bench` (what ``wavestack sim
align-bench`` serves) in this process: the host side reaches it only through its transports (GCS
over TCP, the camera's USB bus over TCP, the piezo over TCP), with the shipped real-bench example
(``config/tma-alignment-remote.toml``) pointed at its ports. Faults are injected through the
simulators' switches.
"""

from __future__ import annotations

import threading
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from remote_bench import addresses, write_real_config
from wavestack.align import AlignPhase, TermFitter
from wavestack.align.loop import AlignmentLoop, AlignSummary
from wavestack.align.session import open_session, options_of
from wavestack.align.station_source import fixed_aperture
from wavestack.cli.sim_align_bench import announcements, open_remote_bench
from wavestack.config.align import load_align_config
from wavestack.config.schema import ConfigError
from wavestack.pipeline import InputError
from wavestack.pipeline.telescope import HexapodPose, ReferenceTilt, TmaModel, build_sensitivity

SIM = load_align_config()
MOUNT = HexapodPose(0.12, -0.2, 0.15, 0.015, -0.02, 0.0)


def _real_config(folder: Path, urls: dict[str, str] | None = None, **align: object):
    urls = urls or {"hexapod": "tcp://127.0.0.1:1", "field_stage": "tcp://127.0.0.1:2",
                    "camera": "usbtcp://127.0.0.1:3/X", "piezo": "socket://127.0.0.1:4"}
    return load_align_config(write_real_config(folder, urls, **align))


def test_the_example_is_a_real_bench(tmp_path: Path) -> None:
    config = _real_config(tmp_path)
    assert not config.align.simulated and config.align.settle_s > 0
    assert config.station_path() == (tmp_path / "tma-alignment-remote-station.toml").resolve()
    assert config.design == SIM.design  # the telescope the remote simulator serves


def test_a_real_bench_without_a_station_is_refused_naming_the_key(tmp_path: Path) -> None:
    config = _real_config(tmp_path)
    config = replace(config, align=replace(config.align, station=None))
    with ExitStack() as stack, pytest.raises(InputError, match=r"\[align\] station: required with simulated = false"):
        open_session(config, stack)


def test_a_missing_controller_url_is_refused_naming_the_key(tmp_path: Path) -> None:
    path = write_real_config(tmp_path, {"hexapod": "tcp://127.0.0.1:1", "field_stage": "tcp://127.0.0.1:2",
                                        "camera": "usbtcp://127.0.0.1:3", "piezo": "socket://127.0.0.1:4"})
    text = path.read_text().replace('url = "tcp://127.0.0.1:2"', "")
    path.write_text(text)
    with pytest.raises(ConfigError, match=r"\[field_stage\].*url"):
        load_align_config(path)


def test_unreachable_controllers_are_a_device_error_and_nothing_is_left_open(tmp_path: Path) -> None:
    config = _real_config(tmp_path)
    with ExitStack() as stack, pytest.raises(Exception, match="127.0.0.1:1") as caught:
        open_session(config, stack)
    assert "Device" in type(caught.value).__name__ or isinstance(caught.value, OSError)


# ----------------------------------------------------------------------------------------- the fit without tilt
def _fitter(remove_tilt: bool) -> TermFitter:
    return TermFitter(fixed_aperture(TmaModel(SIM.design).pupil_mask, 2), SIM.align.max_noll,
                      remove_tilt=remove_tilt)


def test_a_plane_is_invisible_to_the_tilt_free_fit() -> None:
    fitter = _fitter(True)
    rng = np.random.default_rng(4)
    waves = fitter.synthesise(rng.normal(0, 0.1, fitter.count))
    tilted = waves + ReferenceTilt(0.013, -0.021).plane(waves.shape) + 3.0
    assert fitter.count == SIM.align.max_noll - 3 and fitter.first_noll == 4
    assert np.allclose(fitter.terms(tilted), fitter.terms(waves), atol=1e-9)
    assert fitter.rms(tilted) == pytest.approx(fitter.rms(waves), abs=1e-9)
    assert fitter.rms(tilted) < np.std(tilted[fitter.mask])  # the plain RMS would judge the tilt


@pytest.mark.parametrize("at", [np.zeros(5), np.array([0.3, -0.3, 0.3, -0.03, 0.03])], ids=["design", "corner"])
def test_the_five_dofs_stay_observable_without_tilt(at: np.ndarray) -> None:
    """Singular values of the normalised matrix with Noll 2, 3 dropped: all five above the threshold.

    Measured (design point): 1.04, 0.093, 0.032, 0.019, 0.0068 waves per normalised unit (0.1 mm,
    0.01 deg), smallest/largest 6.5e-3 against rcond 1e-3; with tilt the ratio is 1.6e-3 (the tilt
    rows dominate the largest value).
    """
    model = TmaModel(SIM.design)
    values = {}
    for remove in (False, True):
        s = build_sensitivity(model.wavefront, SIM.design.field_points_deg, _fitter(remove), at=at,
                              steps=np.array(SIM.align.steps), scales=np.array(SIM.align.scales))
        values[remove] = np.linalg.svd(s.matrix, compute_uv=False)
    reduced = values[True]
    assert reduced.shape == (5,)
    assert reduced[-1] / reduced[0] > 3 * SIM.align.rcond, reduced
    assert reduced[-1] > 1e-3  # waves per normalised unit: far above the station's ~1e-3 waves noise averaged
    assert reduced[-1] / reduced[0] > values[False][-1] / values[False][0]


# ----------------------------------------------------------------------------------------- the remote bench
def _open(stack: ExitStack, tmp_path: Path, mount: HexapodPose = MOUNT, **align: object):
    remote = open_remote_bench(SIM, stack, piezo_port=0, mount=mount)
    urls = addresses(announcements(remote, "127.0.0.1"))
    config = _real_config(tmp_path, urls, **align)
    return remote, config, open_session(config, stack)


def _run(remote, config, session, arm=None) -> tuple[AlignSummary, tuple[str, ...]]:
    loop = AlignmentLoop(**session.loop_arguments(), options=options_of(config), stop=threading.Event(),
                         on_event=(lambda phase, reason: arm(phase, reason)) if arm else None)
    summary = loop.run()
    return summary, remote.bench.hexapod.controller.commands


@pytest.mark.slow
def test_nothing_simulated_on_the_host_side_and_it_converges(tmp_path: Path) -> None:
    with ExitStack() as stack:
        remote, config, session = _open(stack, tmp_path)
        assert session.bench is None and session.fitter.remove_tilt
        assert session.station is not None and session.station.service.devices.bench is None  # a camera, not a sim
        summary, _ = _run(remote, config, session)
        final = remote.bench.hexapod_pose()
    assert summary.state.phase is AlignPhase.TARGET_MET, summary.state.reason
    assert summary.state.iterations_done <= 5
    assert max(summary.iterations[-1].rms_waves) <= config.align.target_rms_waves
    # the hexapod undid the mount error (as-built errors of M1, M3 leave a little to compensate)
    assert np.allclose(np.array(final.as_tuple()[:3]), -np.array(MOUNT.as_tuple()[:3]), atol=0.03)


def _assert_halted(summary: AlignSummary, commands: tuple[str, ...]) -> None:
    assert summary.state.phase is AlignPhase.FAULTED, summary.state
    assert summary.halted is True
    last_stop = max(i for i, c in enumerate(commands) if c in ("#24", "\x18"))
    assert not any(c.startswith("MOV") for c in commands[last_stop:])


def test_a_controller_error_halts(tmp_path: Path) -> None:
    with ExitStack() as stack:
        remote, config, session = _open(stack, tmp_path)

        def arm(phase, reason):
            if phase == "checking" and "all measured" in reason:
                remote.bench.hexapod.faults.fail_next(7, command="MOV")
        summary, commands = _run(remote, config, session, arm)
    _assert_halted(summary, commands)
    assert "hexapod move refused or failed" in (summary.state.reason or "")


def test_a_dropped_controller_connection_halts(tmp_path: Path) -> None:
    with ExitStack() as stack:
        remote, config, session = _open(stack, tmp_path)

        def arm(phase, reason):
            if phase == "checking" and "all measured" in reason:
                remote.bench.hexapod.faults.drop_connection(command="MOV")
        summary, commands = _run(remote, config, session, arm)
    _assert_halted(summary, commands)
    assert "hexapod" in (summary.state.reason or "")


def test_a_camera_gone_for_good_refuses_the_measurement_and_halts(tmp_path: Path) -> None:
    with ExitStack() as stack:
        remote, config, session = _open(stack, tmp_path, measure_timeout_s=8.0)
        moves_before = []

        def arm(phase, reason):
            if phase == "moving-field" and reason == "read-back within tolerance":
                moves_before.append(sum(c.startswith("MOV") for c in remote.bench.hexapod.controller.commands))
                remote.usb.stop()  # the camera's bus is gone: the station cannot reopen it
        summary, commands = _run(remote, config, session, arm)
    _assert_halted(summary, commands)
    assert "refused" in (summary.state.reason or ""), summary.state.reason
    assert moves_before, [r.rms_waves for r in summary.iterations]
    assert sum(c.startswith("MOV") for c in commands) == moves_before[0] == 1  # no move after the loss


@pytest.mark.slow
def test_a_camera_that_drops_and_returns_costs_no_stale_map(tmp_path: Path) -> None:
    """A dropped USB connection: the station reopens the camera; the loop measures on and converges."""
    with ExitStack() as stack:
        remote, config, session = _open(stack, tmp_path)

        def arm(phase, reason):
            if phase == "moving-field" and reason == "read-back within tolerance":
                remote.lose_camera()
        summary, _ = _run(remote, config, session, arm)
    assert summary.state.phase is AlignPhase.TARGET_MET, summary.state.reason


def test_the_bench_simulator_refuses_a_non_loopback_host_without_allow_remote() -> None:
    from wavestack.cli.sim_align_bench import run_align_bench_simulator
    with pytest.raises(ValueError, match="--allow-remote"):
        run_align_bench_simulator(None, "0.0.0.0", (0, 0, 0), False, None, lambda line: None, threading.Event())
