"""One alignment end to end through the camera: the station's PSI maps of the TMA's wavefront.

The simulated U3V camera and piezo look at a test optic whose surface the bench sets to the TMA's
wavefront (SurfaceCoupling); the station unwraps, the loop averages its maps on the fixed aperture
and fits them with the sensitivity matrix's fitter. The start is inside the fringes' range
(+-0.05 mm, +-0.005 deg: about 10 waves RMS; from +-0.3 mm the fringes alias on this 256 x 128
grid, docs/alignment.md).
"""

from __future__ import annotations

import threading
from contextlib import ExitStack
from pathlib import Path

import numpy as np
import pytest

from wavestack.align import AlignPhase
from wavestack.align.loop import AlignmentLoop
from wavestack.align.session import open_session, options_of
from wavestack.config.align import DEFAULT_CONFIG, load_align_config
from wavestack.simulators.tma import HexapodPose

STATION = DEFAULT_CONFIG.parent / "tma-alignment-station.toml"


def _config(tmp_path: Path):
    text = DEFAULT_CONFIG.read_text(encoding="utf-8").replace(
        '# station = "tma-alignment-station.toml"', f'station = "{STATION}"  #')
    path = tmp_path / "align-station.toml"
    path.write_text(text, encoding="utf-8")
    return load_align_config(path)


def test_the_station_sees_the_bench_wavefront(tmp_path: Path) -> None:
    """Sign, orientation and scale: the station's map equals the model's wavefront on the fixed aperture."""
    config = _config(tmp_path)
    with ExitStack() as stack:
        session = open_session(config, stack, mount=HexapodPose(0.0, 0.01, 0.01, 0.001, 0.0, 0.0))
        measured = session.measure(0)
        truth = session.bench.wavefront().waves
    mask = session.fitter.mask
    truth = truth[mask] - truth[mask].mean()
    # PSI of a 12-bit camera with 0.005 read noise and 0.02 rad vibration: ~1e-3 waves RMS of error
    assert np.std(measured.waves[mask] - truth) < 0.01 * np.std(truth)
    assert np.std(truth) > 0.3  # a real misalignment, not a flat


@pytest.mark.slow
def test_alignment_through_the_camera_converges(tmp_path: Path) -> None:
    config = _config(tmp_path)
    mount = HexapodPose(0.05, -0.04, 0.05, 0.005, -0.004, 0.0)
    with ExitStack() as stack:
        session = open_session(config, stack, mount=mount)
        summary = AlignmentLoop(**session.loop_arguments(), options=options_of(config),
                                stop=threading.Event()).run()
    assert summary.state.phase is AlignPhase.TARGET_MET, summary.state.reason
    assert summary.state.iterations_done <= 5
    assert max(summary.iterations[0].rms_waves) > 1.0
    assert max(summary.iterations[-1].rms_waves) <= 1 / 14
