"""Tests for wavestack.pipeline.phase.carrier: single-frame Fourier-transform (Takeda) phase.

Synthetic frames are I = A + B cos(phi + 2 pi (fx x + fy y)) with x = col, y = -row, inside a
disk of radius 0.42 * side (dark speckle-free surround), phi a sum of defocus, astigmatism and
spherical aberration (even in x and y, so phi has no mean tilt and the carrier is unambiguous).

Tolerances: the sideband crop reaches |f| / 2 towards DC (|f| across the fringes), which limits
the spatial resolution to about 2 / |f| px, so errors concentrate within that distance of the
aperture edge; phase errors are taken inside 0.85 of the disk radius (an edge margin of 32 px on
512 px frames, >= 3 resolution lengths) after removing the mean offset. Noise-free RMS errors
measured there are 0.006-0.014 rad unmasked and 0.003-0.010 rad masked (the finite window smooths
the curved fringes, and a carrier error of 2e-5 cycles/px leaves 0.05 rad of tilt across the
disk), so 0.03 rad is the bound; carrier estimates are within 2.5e-5 cycles/px of the truth,
bound 1e-3 as specified.
"""

from __future__ import annotations


import cv2
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from wavestack.pipeline.phase.carrier import CarrierResult, carrier_phase
from wavestack.pipeline.phase.carrier_spectrum import _crop_rho
from wavestack.pipeline.phase.psi.algorithms import four_step

from shared_data import DATA

PSI = DATA / "psi-mirror-654nm"
SIZE = 512
NO_CARRIER = "frame: no carrier fringes found; expected tilt fringes"

# ----------------------------------------------------------------------------- helpers


def _geometry(size: int = SIZE) -> tuple[NDArray[np.float64], ...]:
    """Pixel x (= col), y (= -row); normalised u, v over the disk; squared normalised radius."""
    rows, cols = np.mgrid[:size, :size].astype(np.float64)
    radius = 0.42 * size
    u = (cols - (size - 1) / 2) / radius
    v = -(rows - (size - 1) / 2) / radius
    return cols, -rows, u, v, u * u + v * v


def _phase(size: int = SIZE, scale: float = 1.0) -> NDArray[np.float64]:
    _, _, u, v, r2 = _geometry(size)
    return scale * (2.0 * (2 * r2 - 1) + 1.0 * (u * u - v * v) + 0.7 * (6 * r2 * r2 - 6 * r2 + 1))


def _frame(
    carrier: tuple[float, float], phase: NDArray[np.float64] | None = None, noise: float = 0.0, seed: int = 0,
) -> NDArray[np.float64]:
    phase = _phase() if phase is None else phase
    x, y, _, _, r2 = _geometry(phase.shape[0])
    disk = r2 <= 1.0
    frame = np.where(disk, 110.0 + 60.0 * np.cos(phase + 2 * np.pi * (carrier[0] * x + carrier[1] * y)), 15.0)
    if noise:
        frame = frame + np.random.default_rng(seed).normal(0.0, noise, frame.shape)
    return frame


def _inner(size: int = SIZE) -> NDArray[np.bool_]:
    return _geometry(size)[4] <= 0.85**2


def _error(result: CarrierResult, truth: NDArray[np.float64], region: NDArray[np.bool_]) -> float:
    """RMS wrapped difference over ``region`` after removing the mean (circular) offset, radians."""
    difference = np.angle(np.exp(1j * (result.phase - truth)))[region]
    difference = np.angle(np.exp(1j * (difference - np.angle(np.mean(np.exp(1j * difference))))))
    return float(np.sqrt(np.mean(difference**2)))


# ----------------------------------------------------------------------------- synthetic


@pytest.mark.parametrize("carrier", [(0.09, 0.04), (0.12, -0.03), (0.0, 0.08), (0.1234, 0.0567)])
@pytest.mark.parametrize("masked", [False, True])
def test_recovers_phase_and_carrier(carrier: tuple[float, float], masked: bool) -> None:
    mask = _geometry()[4] <= 1.0 if masked else None
    result = carrier_phase(_frame(carrier), mask=mask)
    assert np.abs(np.subtract(result.carrier, carrier)).max() < 1e-3
    assert _error(result, _phase(), _inner()) < 0.03
    assert result.window == "hann"
    # float32, as the complex64 sideband it comes from (phase resolution ~1e-7 rad)
    assert result.phase.dtype == np.float32 and result.phase.shape == (SIZE, SIZE)
    assert result.phase.max() <= np.float32(np.pi) and result.phase.min() > -np.float32(np.pi)
    # modulation estimates B = 60 inside, little outside the disk (beyond the window's reach)
    assert np.median(result.modulation[_inner()]) == pytest.approx(60.0, rel=0.05)
    assert np.median(result.modulation[_geometry()[4] > 1.3**2]) < 3.0


def test_noise_raises_the_error_only_moderately() -> None:
    # sigma 10 on B = 60: the Hann-weighted crop passes an effective area of about |f|^2 of the
    # spectrum, so the phase noise is about sigma / B * sqrt(2 |f|^2) ~ 0.02 rad; measured
    # 0.019 rad in total (0.014 rad with the former circular crop of radius |f| / 2)
    result = carrier_phase(_frame((0.09, 0.04), noise=10.0, seed=1))
    assert np.abs(np.subtract(result.carrier, (0.09, 0.04))).max() < 1e-3
    assert _error(result, _phase(), _inner()) < 0.05


@pytest.mark.parametrize("window", ["hann", "tukey", "rect"])
def test_every_window_recovers_the_phase(window: str) -> None:
    result = carrier_phase(_frame((0.1, 0.05)), window=window)
    assert result.window == window
    assert _error(result, _phase(), _inner()) < 0.03


def test_sign_minus_one_negates_phase_and_carrier() -> None:
    frame = _frame((0.09, 0.04))
    plus = carrier_phase(frame)
    minus = carrier_phase(frame, sign=-1)
    assert minus.carrier == (-plus.carrier[0], -plus.carrier[1])
    np.testing.assert_allclose(np.angle(np.exp(1j * (minus.phase + plus.phase))), 0.0, atol=1e-12)
    np.testing.assert_array_equal(minus.modulation, plus.modulation)
    assert np.all((minus.phase > -np.pi) & (minus.phase <= np.pi))


def test_a_carrier_pointing_into_the_other_half_plane_needs_sign_minus_one() -> None:
    """Tilt along (-fx, +fy): the data alone report the sideband at (+fx, -fy) and give -phi."""
    true = (-0.09, 0.04)
    frame = _frame(true)
    automatic = carrier_phase(frame)
    np.testing.assert_allclose(automatic.carrier, (0.09, -0.04), atol=1e-3)
    assert _error(automatic, -_phase(), _inner()) < 0.03
    matched = carrier_phase(frame, sign=-1)
    np.testing.assert_allclose(matched.carrier, true, atol=1e-3)
    assert _error(matched, _phase(), _inner()) < 0.03


def test_an_explicit_carrier_selects_its_sideband() -> None:
    true = (-0.09, 0.04)
    frame = _frame(true)
    given = carrier_phase(frame, carrier=true)
    assert given.carrier == true
    assert _error(given, _phase(), _inner()) < 0.03
    other = carrier_phase(frame, carrier=(0.09, -0.04))
    assert _error(other, -_phase(), _inner()) < 0.03


def test_carrier_and_phase_shifting_give_the_same_phase() -> None:
    """The shared convention: PSI frames A + B cos(phi + k pi/2) and a carrier frame agree."""
    phase = _phase(scale=1.5)
    psi = four_step(np.stack([110.0 + 60.0 * np.cos(phase + k * np.pi / 2) for k in range(4)]))
    fourier = carrier_phase(_frame((0.1, 0.03), phase))
    difference = np.angle(np.exp(1j * (fourier.phase - psi.phase)))[_inner()]
    difference -= np.angle(np.mean(np.exp(1j * difference)))
    assert np.sqrt(np.mean(np.angle(np.exp(1j * difference)) ** 2)) < 0.03


def test_positive_tilt_in_phi_moves_the_carrier_estimate_not_the_sign() -> None:
    """A tilt in phi is indistinguishable from carrier: it is absorbed in the estimate (+x tilt
    of 0.01 cycles/px adds 0.01 to fx), leaving the rest of phi."""
    x, _, _, _, _ = _geometry()
    tilted = _phase() + 2 * np.pi * 0.01 * x
    result = carrier_phase(_frame((0.08, 0.04), tilted))
    np.testing.assert_allclose(result.carrier, (0.09, 0.04), atol=1e-3)
    assert _error(result, _phase(), _inner()) < 0.03


@pytest.mark.parametrize("cycles", [(30.0, 18.0), (35.0, 0.0), (18.0, -30.0)])
def test_a_sideband_wider_than_half_the_carrier_across_it_is_kept(cycles: tuple[float, float]) -> None:
    """Small frame (256 px, about 35 fringes): a cylinder of phase across the fringes moves the
    local fringe frequency up to 0.7 |f| away from the carrier, perpendicular to it (never towards
    DC). A crop of radius |f| / 2 cuts that part of the sideband off: the modulation there drops
    to ~0 and the phase breaks up (measured 0.62 rad RMS). Only the half-way line to DC (and to
    the conjugate sideband) limits the crop; across the carrier it may reach further."""
    size = 256
    carrier = (cycles[0] / size, cycles[1] / size)
    x, y, _, _, r2 = _geometry(size)
    x, y = x - (size - 1) / 2, y + (size - 1) / 2  # from the disk centre, px (y up)
    radius = 0.42 * size
    magnitude = float(np.hypot(*carrier))
    across = (x * -carrier[1] + y * carrier[0]) / magnitude  # px, perpendicular to the fringes
    chirp = 0.7 * magnitude / radius  # local frequency offset per px across, cycles/px^2
    truth = np.pi * chirp * across**2  # radians: 2 pi * integral of (chirp * across)
    result = carrier_phase(_frame(carrier, truth))
    # phi is even across the carrier: no mean tilt, so the estimate is the carrier itself.
    # Measured within 0.025 bins (1e-4 cycles/px; 0.23-0.59 bins when the centroid only saw a
    # circle of radius |f| / 2 of this spread sideband); bound 3e-4 cycles/px.
    assert np.abs(np.subtract(result.carrier, carrier)).max() < 3e-4
    inner = r2 <= 0.85**2
    # every local fringe frequency inside the disk passes the window: no modulation drop-out
    # (measured >= 0.35 B, the Hann weight at 0.6 |f|; 0.01 B with the |f| / 2 crop)
    assert result.modulation[inner].min() > 0.2 * 60.0
    # low orders: piston and the tilt of the (small) residual carrier error taken out, as a
    # Zernike fit with PTT removal does. Measured 0.008 rad RMS (0.62 rad with the |f| / 2
    # crop); bound 0.03 rad as for the other noise-free frames.
    offset = np.subtract(result.carrier, carrier)
    untilted = truth - 2 * np.pi * (offset[0] * x + offset[1] * y)
    assert _error(result, untilted, inner) < 0.03


@settings(max_examples=60, deadline=None)
@given(
    st.floats(-0.45, 0.45), st.floats(-0.45, 0.45), st.floats(0.0, 2 * np.pi), st.floats(0.0, 1.5)
)
def test_the_sideband_crop_never_reaches_nearer_another_lobe(
    f_row: float, f_col: float, angle: float, scale: float
) -> None:
    """Inside the crop (rho < 1) a frequency is nearer the carrier than DC, the conjugate
    sideband and their aliases one sampling frequency away, and within |f| of the carrier."""
    carrier = np.array([f_row, f_col])
    magnitude = float(np.hypot(*carrier))
    assume(magnitude >= 0.01)  # smaller carriers give fewer than 4 fringes on any frame accepted
    offset = scale * magnitude * np.array([np.cos(angle), np.sin(angle)])
    rho = float(_crop_rho((np.array(offset[0]), np.array(offset[1])), (f_row, f_col)))
    point = carrier + offset
    lobes = (0 * carrier, -carrier)  # DC and the conjugate sideband
    others = [np.array([i, j]) + lobe for i in (-1, 0, 1) for j in (-1, 0, 1) for lobe in lobes]
    nearest_other = min(float(np.hypot(*(point - lobe))) for lobe in others)
    if rho < 1.0:
        # 1e-12: rounding of the two distances on the boundary itself
        assert float(np.hypot(*offset)) < nearest_other + 1e-12
        assert float(np.hypot(*offset)) <= magnitude * (1 + 1e-12)
    else:  # and the crop is as large as that allows
        assert float(np.hypot(*offset)) >= min(nearest_other, magnitude) - 1e-12


@pytest.mark.parametrize(
    "frame",
    [
        pytest.param(np.random.default_rng(2).normal(100.0, 5.0, (SIZE, SIZE)), id="noise"),
        pytest.param(np.full((SIZE, SIZE), 128, np.uint8), id="flat"),
        pytest.param(
            200.0 * np.exp(-((np.mgrid[:SIZE, :SIZE] - SIZE / 2) ** 2).sum(0) / (2 * 120.0**2))
            + np.random.default_rng(3).normal(0.0, 2.0, (SIZE, SIZE)),
            id="smooth-blob",
        ),
        pytest.param(
            np.where(_geometry()[4] <= 1, 110.0 + 60.0 * np.cos(40.0 * _geometry()[4]), 15.0), id="closed-fringes"
        ),
    ],
)
def test_a_frame_without_carrier_fringes_raises(frame: NDArray) -> None:
    with pytest.raises(ValueError, match=NO_CARRIER):
        carrier_phase(frame)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"frame": np.zeros((3, SIZE, SIZE))}, "frame: expected a 2-D"),
        ({"frame": np.zeros((8, 8))}, "frame: expected at least 16x16"),
        ({"frame": np.full((SIZE, SIZE), np.nan)}, "frame: expected finite"),
        ({"frame": np.zeros((SIZE, SIZE), complex)}, "frame: expected real numbers"),
        ({"mask": np.ones((SIZE, SIZE))}, "mask: expected a boolean"),
        ({"mask": np.ones((4, 4), bool)}, "mask: expected shape"),
        ({"mask": np.zeros((SIZE, SIZE), bool)}, "mask: expected at least"),
        ({"carrier": (0.1,)}, "carrier: expected two finite"),
        ({"carrier": (0.6, 0.0)}, "carrier: expected \\|fx\\|"),
        ({"carrier": (0.001, 0.0)}, "carrier: expected at least 4 fringes"),
        ({"carrier": "up"}, "carrier"),
        ({"window": "gauss"}, "window: expected one of"),
        ({"sign": 0}, "sign: expected \\+1 or -1"),
        ({"sign": True}, "sign: expected \\+1 or -1"),
        ({"min_carrier_cycles": 0.0}, "min_carrier_cycles: expected a positive"),
    ],
)
def test_bad_input_raises_value_error_naming_the_argument(kwargs: dict, match: str) -> None:
    arguments = {"frame": _frame((0.09, 0.04))} | kwargs
    frame = arguments.pop("frame")
    with pytest.raises(ValueError, match=match):
        carrier_phase(frame, **arguments)


# ----------------------------------------------------------------------------- real frames


@pytest.mark.skipif(not PSI.is_dir(), reason="real PSI frames not available")
def test_real_carrier_frame_gives_a_smooth_phase_on_the_mirror() -> None:
    """Image197: measured carrier (0.0369, -0.0005) cycles/px, i.e. ~21 near-vertical fringes
    across the 560 px mirror; after removal the mirror shows its few defocus / spherical rings."""
    frame = cv2.imread(str(PSI / "Image197.jpg"), cv2.IMREAD_GRAYSCALE)
    assert frame is not None and frame.shape == (600, 800)
    result = carrier_phase(frame)
    fx, fy = result.carrier
    assert 0.03 < fx < 0.045 and abs(fy) < 0.005
    rows, cols = np.mgrid[:600, :800]
    radius = np.hypot(rows - 300.0, cols - 395.0)  # mirror disk: radius ~280 px (see test_psi)
    mirror = radius < 0.8 * 280.0
    assert np.isfinite(result.phase[mirror]).all()
    halo = (radius > 1.15 * 280.0) & (radius < 1.35 * 280.0)
    assert np.median(result.modulation[mirror]) > 4.0 * np.median(result.modulation[halo])
    # along the middle row the carrier alone would wrap ~2 pi x 0.037 x 450 / 2 pi = 17 times
    line = result.phase[300, 395 - 225: 395 + 225]
    wraps = np.count_nonzero(np.abs(np.diff(line)) > np.pi)
    assert wraps <= 6, wraps


@pytest.mark.skipif(not PSI.is_dir(), reason="real PSI frames not available")
def test_real_phase_shifting_frame_has_no_carrier() -> None:
    """Image5 shows closed rings (no tilt): the spectrum is a ring, not a sideband."""
    frame = cv2.imread(str(PSI / "Image5.jpg"), cv2.IMREAD_GRAYSCALE)
    with pytest.raises(ValueError, match=NO_CARRIER):
        carrier_phase(frame)
