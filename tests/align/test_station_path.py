"""The default alignment measures through the camera: the station's PSI maps of the TMA's wavefront.

The simulated U3V camera and piezo look at a test optic whose surface the bench sets to the TMA's
wavefront less the tilt the interferometer's reference takes out (SurfaceCoupling, the return spot
centred); the station unwraps, the loop averages its maps on the fixed aperture, adds the
reference's tilt back and fits them with the sensitivity matrix's CSF-QCM fitter. Over the stated
range (+-0.3 mm, +-0.03 deg: up to 57 waves RMS) the fringes stay under 0.15 waves per pixel once
the tilt is out; with the tilt on them they alias (docs/alignment.md).
"""

from __future__ import annotations

from contextlib import ExitStack
from dataclasses import replace

import numpy as np
import pytest

from wavestack.align.fringes import MAX_SLOPE_WAVES_PER_PX, fringe_slope_bound, pixel_slope
from wavestack.align.session import check_fringes, open_session
from wavestack.config.align import load_align_config
from wavestack.pipeline import InputError
from wavestack.simulators.align_bench import draw_mount
from wavestack.simulators.tma import HexapodPose, TmaModel

CONFIG = load_align_config()


def test_the_default_measures_through_the_station_with_csf_qcm() -> None:
    assert CONFIG.station_path() is not None and CONFIG.station_path().is_file()
    assert CONFIG.align.fit_method == "csf-qcm" and CONFIG.align.null_tilt


@pytest.mark.parametrize("mount", [HexapodPose(0.0, 0.01, 0.01, 0.001, 0.0, 0.0), draw_mount(0.3, 0.3, 0.03, 3)],
                         ids=["small", "full-range"])
def test_the_station_sees_the_bench_wavefront(mount: HexapodPose) -> None:
    """Sign, orientation, scale and tilt: the station's map equals the model's wavefront on the fixed aperture."""
    with ExitStack() as stack:
        session = open_session(CONFIG, stack, mount=mount)
        measured = session.measure(0)
        truth = session.bench.wavefront().waves
    mask = session.fitter.mask
    truth = np.where(mask, truth - np.nanmean(truth[mask]), np.nan)
    assert np.nanstd(truth) > 0.3  # a real misalignment, not a flat
    # PSI of a 12-bit camera with 0.005 read noise and 0.02 rad vibration: ~1e-3 waves RMS of error
    error = measured.waves[mask] - truth[mask]
    assert np.std(error) < 0.01 * np.nanstd(truth), np.std(error)
    terms = session.fitter.terms(measured.waves) - session.fitter.terms(truth)
    assert np.linalg.norm(terms) < 0.01 * np.linalg.norm(session.fitter.terms(truth))


def test_the_full_range_aliases_without_the_reference_tilt() -> None:
    """The tilt is what aliases: 2 waves per pixel with it, under the bound without it."""
    model = TmaModel(CONFIG.design)
    ranges = np.array([0.3, 0.3, 0.3, 0.03, 0.03])
    with_tilt = fringe_slope_bound(model.wavefront, CONFIG.design.field_points_deg[:1], ranges, null_tilt=False)
    nulled = fringe_slope_bound(model.wavefront, CONFIG.design.field_points_deg[:1], ranges)
    assert with_tilt > 1.0 and nulled < MAX_SLOPE_WAVES_PER_PX, (with_tilt, nulled)
    # the bound holds for a drawn mount at the corner of the range
    truth = TmaModel(CONFIG.design, mount=HexapodPose(0.3, -0.3, 0.3, -0.03, 0.03, 0.0))
    actual = np.nanmax(pixel_slope(truth.wavefront(CONFIG.design.field_points_deg[0], HexapodPose())))
    assert actual <= nulled


def test_a_grid_that_would_alias_is_refused() -> None:
    config = replace(CONFIG, align=replace(CONFIG.align, null_tilt=False))
    with pytest.raises(InputError, match=r"null_tilt = false.*expected pixels of at most"):
        check_fringes(config, TmaModel(CONFIG.design))


def test_the_alignment_measures_through_a_gige_camera_as_through_usb3(tmp_path) -> None:  # noqa: ANN001
    """[camera] url = "sim://gige" in the alignment's station file: the same maps through GigE Vision."""
    station = CONFIG.station_path()
    assert station is not None
    text = station.read_text()
    assert 'url = "sim://u3v"' in text
    gige_station = tmp_path / "station-gige.toml"
    gige_station.write_text(text.replace('url = "sim://u3v"', 'url = "sim://gige"'))
    config = replace(CONFIG, align=replace(CONFIG.align, station=str(gige_station)))
    mount = HexapodPose(0.0, 0.01, 0.01, 0.001, 0.0, 0.0)
    with ExitStack() as stack:
        session = open_session(config, stack, mount=mount)
        measured = session.measure(0)
        truth = session.bench.wavefront().waves
    mask = session.fitter.mask
    truth = np.where(mask, truth - np.nanmean(truth[mask]), np.nan)
    error = measured.waves[mask] - truth[mask]
    assert np.std(error) < 0.01 * np.nanstd(truth), np.std(error)  # as through USB3 Vision, above
