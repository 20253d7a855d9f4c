"""The one entry every command uses: a request checked against the area once, then figures per map."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wavestack.pipeline.surface import SurfaceAnalyzer, SurfaceRequest, parse_areal_filter, parse_form_tolerance


def _disk(size: int = 129) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rows, cols = np.indices((size, size))
    x, y = (cols - (size - 1) / 2) / 60, ((size - 1) / 2 - rows) / 60
    return x * x + y * y <= 1, x, y


def test_everything_requested_is_measured_and_reported_in_json() -> None:
    mask, x, y = _disk()
    request = SurfaceRequest(tolerance=parse_form_tolerance("3/1(0.5/0.2; RMSi < 0.1)"), psd=True,
                             band_per_mm=(0.2, 2.0), slope_length_mm=0.5, areal_filter=parse_areal_filter("hp:2"))
    analyzer = SurfaceAnalyzer(mask, request, pixel_mm=0.1)
    surface = 120 * (x * x + y * y) + 20 * x * y + 3 * np.sin(2 * np.pi * 6 * x)
    figures = analyzer.measure(np.where(mask, surface, np.nan))
    report = json.loads(json.dumps(figures.as_dict()))
    assert set(report) == {"form", "pvr", "spec", "psd", "slope", "filtered"}
    assert report["form"]["fringes"]["SAG"] == pytest.approx(report["form"]["nm"]["SAG"] / (546.07 / 2))
    assert report["form"]["waves"]["IRR"] == pytest.approx(report["form"]["nm"]["IRR"] / 546.07)
    assert [c["quantity"] for c in report["spec"]["checks"]] == ["SAG", "IRR", "RSI", "RMSi"]
    assert report["spec"]["passed"] is all(c["passed"] for c in report["spec"]["checks"])
    assert report["psd"]["band_per_mm"] == [0.2, 2.0] and report["psd"]["band_rms_nm"] > 0
    assert len(report["psd"]["frequency_per_mm"]) == len(report["psd"]["azimuthal_nm2_mm2"])
    assert report["slope"]["integration_length_mm"] == 0.5 and report["filtered"]["kind"] == "hp"
    # the heavy figures can be left out of a result (the live station does, between spectra)
    light = analyzer.measure(np.where(mask, surface, np.nan), spectral=False)
    assert light.psd is None and light.filtered is None and light.slope is not None
    assert light.form == figures.form


def test_the_fringes_wavelength_is_the_drawings_or_the_one_given() -> None:
    mask, x, _ = _disk()
    tolerance = parse_form_tolerance("3/1(0.5) lambda = 632.8 nm")
    assert SurfaceAnalyzer(mask, SurfaceRequest(tolerance=tolerance)).measure(x).wavelength_nm == 632.8
    assert SurfaceAnalyzer(mask, SurfaceRequest()).measure(x).wavelength_nm == 546.07
    assert SurfaceAnalyzer(mask, SurfaceRequest(wavelength_nm=600.0)).measure(x).wavelength_nm == 600.0


def test_a_failing_part_names_its_limiting_quantity() -> None:
    mask, x, y = _disk()
    figures = SurfaceAnalyzer(mask, SurfaceRequest(tolerance=parse_form_tolerance("3/5(0.5/0.2)"))).measure(
        np.where(mask, 200 * x * y, np.nan))  # 200 nm PV of astigmatism: IRR 0.73 fringes, no sag or RSI
    verdict = figures.verdict
    assert not verdict.passed and verdict.limiting.quantity == "IRR"
    assert [c.passed for c in verdict.checks] == [True, False, True]
    assert verdict.summary().startswith("3/5(0.5/0.2): FAIL, limiting IRR 0.7")


@pytest.mark.parametrize(("request_", "pixel", "message"), [
    (SurfaceRequest(psd=True), None, r"pixel size: the PSD, slopes and filters need the pixel pitch"),
    (SurfaceRequest(band_per_mm=(0.001, 1.0)), 0.1, r"PSD band 0\.001-1 cycles/mm .*expected a band inside it"),
    (SurfaceRequest(band_per_mm=(0.5, 8.0)), 0.1, r"PSD band 0\.5-8 cycles/mm .*resolves 0\.0\d+-5 cycles/mm"),
    (SurfaceRequest(slope_length_mm=0.1), 0.1, r"slope integration length 0\.1 mm is 1 pixels .*at least 2 pixels"),
    (SurfaceRequest(areal_filter=parse_areal_filter("lp:40")), 0.1, r"filter lp:40: cut-off 40 mm is outside"),
])
def test_a_request_the_sampling_cannot_serve_is_refused_before_any_map(request_, pixel, message) -> None:
    mask, _, _ = _disk()
    with pytest.raises(ValueError, match=message) as caught:
        SurfaceAnalyzer(mask, request_, pixel_mm=pixel)
    assert "\n" not in str(caught.value)
