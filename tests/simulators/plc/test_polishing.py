"""The polishing-station model: a closed loop converges, commands apply once per id, ranges hold."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wavestack.simulators.plc import PolishingPass, PolishingStation, RemovalCommand

N_TERMS = 15  # Noll 1..15


def _rms_from_4(coefficients: np.ndarray) -> float:
    """Surface rms of Noll terms 4..n, nm (rms-normalised terms: root of the sum of squares)."""
    return float(np.sqrt(np.sum(np.asarray(coefficients)[3:] ** 2)))


def _initial_surface(seed: int) -> np.ndarray:
    # 100 nm per term, clipped so a first command of "remove everything" stays within 500 nm
    return np.clip(np.random.default_rng(seed).normal(0.0, 100.0, N_TERMS), -400.0, 400.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_closed_loop_converges(seed: int) -> None:
    efficiency, spread, noise_nm, measurement_nm = 0.8, 0.05, 0.5, 2.0
    station = PolishingStation(
        _initial_surface(seed), efficiency=efficiency, efficiency_spread=spread, noise_nm=noise_nm, seed=seed
    )
    meter = np.random.default_rng(1000 + seed)  # the interferometer's own noise
    rms0 = _rms_from_4(station.surface_nm)
    iterations = 10
    for command_id in range(1, iterations + 1):
        measured = station.surface_nm + meter.normal(0.0, measurement_nm, N_TERMS)
        station.apply(RemovalCommand(command_id, tuple(measured), passes=1))
    rms_final = _rms_from_4(station.surface_nm)

    # Expected reduction. Per term and iteration c' = (1 - k) c - k m + n, where the achieved
    # efficiency k = efficiency (1 + spread u), |u| <= 1, m is measurement noise and n process noise.
    # The deterministic part shrinks by at most rho = max |1 - k| = 0.24 per iteration
    # (0.24**10 ~ 6e-7); the noise settles at a per-term variance of at most
    # v = (k_max^2 sigma_m^2 + sigma_n^2) / (1 - rho^2) ~ 3.3 nm^2. Over the 12 terms 4..15:
    rho = max(abs(1 - efficiency * (1 - spread)), abs(1 - efficiency * (1 + spread)))
    k_max = efficiency * (1 + spread)
    v_floor = (k_max**2 * measurement_nm**2 + noise_nm**2) / (1 - rho**2)
    n_terms_from_4 = N_TERMS - 3
    expected_rms = math.sqrt(rho ** (2 * iterations) * rms0**2 + n_terms_from_4 * v_floor)
    assert rms0 / expected_rms > 5  # the bound itself promises more than the factor the loop needs
    assert rms0 / rms_final > 5
    # rms_final^2 / v is about chi-square with 12 degrees of freedom: exceeding twice the expected
    # rms (4x the variance, chi2_12 > 48) has probability ~1e-6, so 2x is a safe ceiling.
    assert rms_final < 2.0 * expected_rms
    # ...and polishing never reaches zero: each pass adds independent noise of variance sigma_n^2
    # per term, so rms_final^2 is at least ~12 sigma_n^2 (P(chi2_12 < 12 * 0.1) ~ 1e-5).
    assert rms_final > math.sqrt(0.1 * n_terms_from_4) * noise_nm
    assert station.passes_applied == iterations and station.last_command_id == iterations


def test_single_pass_removes_efficiency_times_request_exactly_without_scatter() -> None:
    surface = np.linspace(-50.0, 50.0, N_TERMS)
    removal = np.linspace(10.0, -10.0, N_TERMS)
    station = PolishingStation(surface, efficiency=0.7, efficiency_spread=0.0, noise_nm=0.0)
    result = station.apply(RemovalCommand(5, tuple(removal), passes=3))
    # three passes of removal/3 each at efficiency 0.7 sum to 0.7 * removal (float rounding only)
    np.testing.assert_allclose(result.removed_nm, 0.7 * removal, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(station.surface_nm, surface - 0.7 * removal, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(result.surface_before_nm, surface)
    np.testing.assert_array_equal(result.surface_after_nm, station.surface_nm)
    assert station.passes_applied == 3


def test_efficiency_spread_bounds_the_removal_per_term() -> None:
    n = 500
    removal = np.full(n, 100.0)
    station = PolishingStation(np.zeros(n), efficiency=0.8, efficiency_spread=0.05, noise_nm=0.0, seed=3)
    removed = station.apply(RemovalCommand(1, tuple(removal))).removed_nm
    # uniform scatter: every term removes between 0.8 * 0.95 and 0.8 * 1.05 of the request,
    # and the scatter really is used (not a constant): it spans most of that interval
    assert np.all(removed >= 76.0 - 1e-9) and np.all(removed <= 84.0 + 1e-9)
    assert removed.max() - removed.min() > 6.0  # 500 uniform draws cover > 75 % of the 8 nm width


@pytest.mark.parametrize("passes", [1, 4])
def test_process_noise_grows_with_the_number_of_passes(passes: int) -> None:
    n = 4000
    station = PolishingStation(np.zeros(n), noise_nm=0.5, seed=11)
    removed = station.apply(RemovalCommand(1, tuple(np.zeros(n)), passes=passes)).removed_nm
    expected_std = 0.5 * math.sqrt(passes)  # independent noise per pass
    # standard error of a sample std is sigma / sqrt(2 n) ~ 0.0056 sigma; allow 5 of them
    assert abs(float(np.std(removed)) - expected_std) < 5 * expected_std / math.sqrt(2 * n)


def test_same_command_id_applies_once() -> None:
    station = PolishingStation(_initial_surface(0), seed=0)
    first = station.apply(RemovalCommand(7, tuple(station.surface_nm)))
    after_first = station.surface_nm
    again = station.apply(RemovalCommand(7, tuple(station.surface_nm)))  # a retry
    different = station.apply(RemovalCommand(7, tuple(np.zeros(N_TERMS)), passes=3))  # same id, other body
    assert again is first and different is first
    np.testing.assert_array_equal(station.surface_nm, after_first)
    assert station.passes_applied == 1
    second = station.apply(RemovalCommand(8, tuple(station.surface_nm)))
    assert second.command_id == 8 and not np.array_equal(station.surface_nm, after_first)
    np.testing.assert_array_equal(second.surface_before_nm, after_first)
    after_second = station.surface_nm
    assert station.apply(RemovalCommand(7, tuple(after_second))) is first  # an old id stays spent
    np.testing.assert_array_equal(station.surface_nm, after_second)
    assert station.passes_applied == 2 and station.last_command_id == 8


def test_pass_arrays_and_surface_are_copies() -> None:
    station = PolishingStation(np.ones(N_TERMS))
    result = station.apply(RemovalCommand(1, tuple(np.ones(N_TERMS))))
    with pytest.raises(ValueError):
        result.surface_after_nm[0] = 0.0
    station.surface_nm[0] = 1e6
    assert station.surface_nm[0] == result.surface_after_nm[0]
    assert isinstance(result, PolishingPass)


@pytest.mark.parametrize(
    ("command", "parameter", "allowed"),
    [
        (RemovalCommand(-1, (0.0,) * N_TERMS), "command_id", "[0, 4294967295]"),
        (RemovalCommand(2**32, (0.0,) * N_TERMS), "command_id", "[0, 4294967295]"),
        (RemovalCommand(True, (0.0,) * N_TERMS), "command_id", "[0, 4294967295]"),  # type: ignore[arg-type]
        (RemovalCommand(1.0, (0.0,) * N_TERMS), "command_id", "[0, 4294967295]"),  # type: ignore[arg-type]
        (RemovalCommand(1, (0.0,) * N_TERMS, passes=0), "passes", "[1, 100]"),
        (RemovalCommand(1, (0.0,) * N_TERMS, passes=101), "passes", "[1, 100]"),
        (RemovalCommand(1, (0.0,) * N_TERMS, passes=2.0), "passes", "[1, 100]"),  # type: ignore[arg-type]
        (RemovalCommand(1, (0.0,) * (N_TERMS - 1)), "removal_nm", "15 terms"),
        (RemovalCommand(1, (0.0,) * 14 + (500.5,)), "removal_nm", "[-500, 500]"),
        (RemovalCommand(1, (-501.0,) + (0.0,) * 14), "removal_nm", "[-500, 500]"),
        (RemovalCommand(1, (math.nan,) + (0.0,) * 14), "removal_nm", "[-500, 500]"),
        (RemovalCommand(1, (math.inf,) + (0.0,) * 14), "removal_nm", "[-500, 500]"),
    ],
)
def test_validation_names_parameter_and_range(command: RemovalCommand, parameter: str, allowed: str) -> None:
    station = PolishingStation(np.full(N_TERMS, 10.0))
    with pytest.raises(ValueError, match=parameter) as info:
        station.validate(command)
    assert allowed in str(info.value)
    with pytest.raises(ValueError, match=parameter):
        station.apply(command)
    np.testing.assert_array_equal(station.surface_nm, np.full(N_TERMS, 10.0))
    assert station.passes_applied == 0 and station.last_command_id is None


def test_rejected_command_does_not_spend_its_id() -> None:
    station = PolishingStation(np.full(N_TERMS, 10.0), noise_nm=0.0, efficiency_spread=0.0)
    with pytest.raises(ValueError):
        station.apply(RemovalCommand(3, (1000.0,) * N_TERMS))
    result = station.apply(RemovalCommand(3, (10.0,) * N_TERMS))
    np.testing.assert_allclose(result.removed_nm, 8.0, rtol=1e-12)  # 0.8 * 10 nm


def test_removal_at_the_limit_is_valid() -> None:
    station = PolishingStation(np.zeros(N_TERMS), max_removal_nm=500.0)
    station.validate(RemovalCommand(0, (500.0,) + (-500.0,) * 14, passes=100))


@pytest.mark.parametrize(
    ("kwargs", "parameter"),
    [
        ({"efficiency": 0.0}, "efficiency"),
        ({"efficiency": 1.2}, "efficiency"),
        ({"efficiency": math.nan}, "efficiency"),
        ({"efficiency_spread": -0.1}, "efficiency_spread"),
        ({"efficiency_spread": 1.0}, "efficiency_spread"),
        ({"noise_nm": -0.5}, "noise_nm"),
        ({"max_removal_nm": 0.0}, "max_removal_nm"),
        ({"initial_surface_nm": []}, "initial_surface_nm"),
        ({"initial_surface_nm": np.zeros((3, 3))}, "initial_surface_nm"),
        ({"initial_surface_nm": [0.0, math.nan]}, "initial_surface_nm"),
    ],
)
def test_construction_errors_name_the_parameter(kwargs: dict[str, object], parameter: str) -> None:
    arguments: dict[str, object] = {"initial_surface_nm": np.zeros(N_TERMS), **kwargs}
    with pytest.raises(ValueError, match=parameter):
        PolishingStation(**arguments)  # type: ignore[arg-type]


def test_removal_command_shape_checked() -> None:
    with pytest.raises(ValueError, match="removal_nm"):
        RemovalCommand(1, np.zeros((2, 3)))  # type: ignore[arg-type]
    assert RemovalCommand(1, np.arange(3.0)).removal_nm == (0.0, 1.0, 2.0)  # type: ignore[arg-type]


def _run_sequence(seed: int) -> list[np.ndarray]:
    station = PolishingStation(_initial_surface(0), seed=seed)
    surfaces = []
    for command_id, passes in enumerate([1, 3, 2], start=1):
        station.apply(RemovalCommand(command_id, tuple(0.5 * station.surface_nm), passes=passes))
        surfaces.append(station.surface_nm)
    return surfaces


def test_deterministic_per_seed() -> None:
    first, again, other = _run_sequence(42), _run_sequence(42), _run_sequence(43)
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(first[-1], other[-1])
