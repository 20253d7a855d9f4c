"""PVr (Evans) on the bundled Zygo map, against an independent computation, and its robustness."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from shared_data import DATA, require_shared_data
from wavestack.pipeline import read_measured_map
from wavestack.pipeline.surface import RobustPVAnalyzer, measured_area


def _fringe_modes(count: int) -> list[tuple[int, int]]:
    """The Fringe (University of Arizona) order: groups of (n + |m|) / 2, |m| falling, cos before sin."""
    modes: list[tuple[int, int]] = []
    group = 0
    while len(modes) < count:
        for m in range(group, -1, -1):
            n = 2 * group - m
            modes.extend([(n, 0)] if m == 0 else [(n, m), (n, -m)])
        group += 1
    return modes[:count]


def _zernike(n: int, m: int, rho: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Z_n^m from the factorial sum (unnormalised: the span is what a least-squares fit sees)."""
    k_max = (n - abs(m)) // 2
    radial = sum((-1) ** k * math.factorial(n - k)
                 / (math.factorial(k) * math.factorial((n + abs(m)) // 2 - k) * math.factorial(k_max - k))
                 * rho ** (n - 2 * k) for k in range(k_max + 1))
    return radial * (np.cos(m * theta) if m >= 0 else np.sin(-m * theta))


def _independent_pvr(surface: np.ndarray, valid: np.ndarray) -> float:
    """Evans' PVr written out: the plane removed, 36 Fringe terms over the enclosing circle, PV + 3 RMS."""
    rows, cols = np.nonzero(valid)
    (cx, cy), radius = cv2.minEnclosingCircle(np.column_stack([cols, rows]).astype(np.float32))
    x, y = (cols - cx) / radius, (cy - rows) / radius
    values = surface[rows, cols]
    plane = np.column_stack([np.ones_like(x), x, y])
    values = values - plane @ np.linalg.lstsq(plane, values, rcond=None)[0]
    rho, theta = np.hypot(x, y), np.arctan2(y, x)
    basis = np.column_stack([_zernike(n, m, rho, theta) for n, m in _fringe_modes(36)])
    fitted = basis @ np.linalg.lstsq(basis, values, rcond=None)[0]
    return float(np.ptp(fitted) + 3.0 * np.std(values - fitted))


def test_the_fringe_order_written_here_is_the_usual_one() -> None:
    modes = _fringe_modes(36)
    assert modes[3] == (2, 0) and modes[8] == (4, 0) and modes[15] == (6, 0) and modes[24] == (8, 0)
    assert modes[35] == (10, 0) and len(set(modes)) == 36


@require_shared_data()
def test_pvr_on_the_zygo_map_within_1_percent_of_an_independent_computation() -> None:
    data = read_measured_map(DATA / "zygo-dat" / "valid_zygo_dat_file.dat")
    pvr = RobustPVAnalyzer(measured_area(np.asarray(data.valid))).measure(data.map_nm)
    expected = _independent_pvr(data.map_nm, np.asarray(data.valid))
    assert pvr.pvr == pytest.approx(expected, rel=0.01)
    assert pvr.pvr == pytest.approx(pvr.fit_pv + 3 * pvr.residual_rms)
    # PVr and PV differ on this map: the comparison is not of two PVs
    assert abs(pvr.pvr - float(np.nanmax(data.map_nm) - np.nanmin(data.map_nm))) > 20.0


def test_pvr_follows_the_surface_not_a_spike() -> None:
    rows, cols = np.mgrid[:129, :129]
    x, y = (cols - 64) / 64, (64 - rows) / 64
    disk = x**2 + y**2 <= 1
    u = x**2 + y**2
    surface = 40.0 * (6 * u**2 - 6 * u + 1) + 15.0 * (3 * u - 2) * x
    analyzer = RobustPVAnalyzer(measured_area(disk))
    clean = analyzer.measure(surface)
    # a surface within the 36 terms: the fit is the surface, the residual nothing
    assert clean.residual_rms < 1e-9
    assert clean.pvr == pytest.approx(np.ptp(surface[disk] - np.polyval(np.polyfit(x[disk], surface[disk], 1), x[disk])),
                                      rel=0.05)
    spiked = surface.copy()
    spiked[64, 90] += 2000.0
    pv_jump = np.ptp(spiked[disk]) - np.ptp(surface[disk])
    pvr_jump = analyzer.measure(spiked).pvr - clean.pvr
    assert pv_jump > 1900.0 and pvr_jump < 0.1 * pv_jump


def test_refuses_a_map_with_a_missing_measured_pixel() -> None:
    disk = np.hypot(*np.mgrid[-20:21, -20:21]) <= 20
    surface = np.where(disk, 0.0, np.nan)
    surface[20, 20] = np.nan
    with pytest.raises(ValueError, match="NaN or infinite"):
        RobustPVAnalyzer(measured_area(disk)).measure(surface)


def test_pixels_left_out_of_a_map_are_measured_around_as_on_an_area_without_them() -> None:
    """``nan_policy="omit"``: the analyzer of the whole area on a map with interior pixels left out
    (a quality mask's, a clip's) gives the PVr an analyzer built on the remaining pixels gives (their
    enclosing circle is the same), and Evans' PVr written out independently on them."""
    rows, cols = np.mgrid[:97, :97]
    x, y = (cols - 48) / 48, (48 - rows) / 48
    disk = x**2 + y**2 <= 1
    u = x**2 + y**2
    surface = 25.0 * (6 * u**2 - 6 * u + 1) + 9.0 * (3 * u - 2) * y + 4.0 * np.cos(7 * x) * np.sin(5 * y)
    left_out = disk & (np.hypot(x - 0.2, y + 0.1) < 0.15)  # a dropout in the interior
    kept = disk & ~left_out
    holed = np.where(kept, surface, np.nan)
    omitted = RobustPVAnalyzer(measured_area(disk)).measure(holed, nan_policy="omit")
    fresh = RobustPVAnalyzer(measured_area(kept)).measure(holed)
    assert omitted.pvr == pytest.approx(fresh.pvr, rel=1e-9)
    assert omitted.fit_pv == pytest.approx(fresh.fit_pv, rel=1e-9)
    assert omitted.pvr == pytest.approx(_independent_pvr(surface, kept), rel=0.01)
    with pytest.raises(ValueError, match="NaN or infinite"):
        RobustPVAnalyzer(measured_area(disk)).measure(holed)
