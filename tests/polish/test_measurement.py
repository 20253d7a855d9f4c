"""The measurement: units, PTT removal, averaging, the noise estimate, and every refusal."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.pipeline import remove_physical_terms
from wavestack.polish.measurement import ApertureKey, average_surface, surface_stats
from wavestack.station import MapSample, UntrustedMeasurement

SHAPE = (48, 48)


def _disc(radius: float = 20.0) -> np.ndarray:
    rows, cols = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    return np.hypot(rows - 23.5, cols - 23.5) <= radius


def _sample(waves: np.ndarray, mask: np.ndarray, *, t_ns: int = 0, aperture_id: int | None = 0,
            valid: bool = True) -> MapSample:
    return MapSample(np.where(mask, waves, np.nan), valid, None if valid else "fit: bad", aperture_id, t_ns)


def _astig(mask: np.ndarray) -> np.ndarray:
    rows, cols = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    x, y = (cols - 23.5) / 20, (rows - 23.5) / 20
    return np.where(mask, x * x - y * y, np.nan)


def test_units_are_nm_of_surface_and_ptt_is_removed() -> None:
    mask = _disc()
    rows, cols = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    shape_waves = 0.1 * _astig(mask)
    tilted = shape_waves + 0.3 + 0.01 * rows - 0.02 * cols  # piston and tilt the loop must not polish
    m = average_surface([_sample(tilted, mask)] * 3, wavelength_nm=632.8, reflection_factor=2.0, min_count=3)
    expected, _ = remove_physical_terms(shape_waves * 632.8 / 2.0, mask, "ptt")
    np.testing.assert_allclose(m.surface_nm[mask], expected[mask], atol=1e-9)
    assert np.all(np.isnan(m.surface_nm[~mask]))
    rms, pv = surface_stats(expected, mask)
    assert m.rms_nm == pytest.approx(rms) and m.pv_nm == pytest.approx(pv)
    assert m.aperture == ApertureKey.of(mask) and m.count == 3


def test_the_target_figure_is_subtracted() -> None:
    mask = _disc()
    target = 30.0 * np.nan_to_num(_astig(mask))
    waves = target * 2.0 / 600.0  # the surface is exactly the target
    m = average_surface([_sample(waves, mask)] * 2, wavelength_nm=600.0, reflection_factor=2.0, min_count=2,
                        target_nm=target)
    assert m.rms_nm < 1e-9


def test_noise_is_the_standard_error_of_the_mean() -> None:
    mask = _disc()
    rng = np.random.default_rng(3)
    sigma_nm, n = 2.0, 16
    base = 0.05 * _astig(mask)
    samples = [_sample(base + rng.normal(0, sigma_nm * 2 / 632.8, SHAPE), mask) for _ in range(n)]
    m = average_surface(samples, wavelength_nm=632.8, reflection_factor=2.0, min_count=n)
    # white noise of sigma per map: the mean's standard error is sigma / sqrt(n); the PTT fit takes
    # 3 of ~1250 degrees of freedom, and the estimate's own scatter is ~1/sqrt(2 * 15 * 1250): 1 %
    assert m.noise_rms_nm == pytest.approx(sigma_nm / np.sqrt(n), rel=0.05)
    with pytest.raises(UntrustedMeasurement, match="noise"):
        average_surface(samples, wavelength_nm=632.8, reflection_factor=2.0, min_count=n, max_noise_rms_nm=0.3)


@pytest.mark.parametrize("problem", ["too-few", "invalid", "stale", "other-id", "other-mask", "reference"])
def test_refusals_name_the_problem(problem: str) -> None:
    mask = _disc()
    waves = 0.1 * _astig(mask)
    samples = [_sample(waves, mask, t_ns=100 + i) for i in range(4)]
    kwargs: dict = {"wavelength_nm": 632.8, "reflection_factor": 2.0, "min_count": 4}
    words = {"too-few": "at least 4", "invalid": "invalid", "stale": "before the machine", "other-id": "aperture id",
             "other-mask": "aperture changed", "reference": "campaign"}
    if problem == "too-few":
        samples = samples[:3]
    elif problem == "invalid":
        samples[2] = _sample(waves, mask, valid=False, t_ns=102)
    elif problem == "stale":
        kwargs["not_before_ns"] = 101
    elif problem == "other-id":
        samples[3] = _sample(waves, mask, aperture_id=1, t_ns=103)
    elif problem == "other-mask":
        samples[1] = _sample(waves, _disc(19.0), t_ns=101)
    else:
        kwargs["reference"] = ApertureKey.of(_disc(19.0))
    with pytest.raises(UntrustedMeasurement, match=words[problem]):
        average_surface(samples, **kwargs)
    kwargs.pop("not_before_ns", None), kwargs.pop("reference", None)
    if problem not in ("too-few",):  # the same call on the clean samples is trusted
        clean = [_sample(waves, mask, t_ns=100 + i) for i in range(4)]
        assert average_surface(clean, **kwargs).count == 4


def test_aperture_key_tells_masks_apart() -> None:
    a, b = _disc(20.0), _disc(20.0)
    b[0, 0] = True  # one pixel more
    assert ApertureKey.of(a) == ApertureKey.of(_disc(20.0))
    assert ApertureKey.of(a) != ApertureKey.of(b)
    assert ApertureKey.of(a).to_json()["pixels"] == int(a.sum())


def test_the_rim_is_taken_off_before_anything_else() -> None:
    mask = _disc()
    waves = np.where(mask, 0.0, np.nan)
    rim = mask & ~np.roll(mask, 1, axis=0)  # the top rim pixels
    waves[rim] = 3.0  # a rim of wild phase, as a low-modulation edge gives
    plain = average_surface([_sample(waves, mask)] * 2, wavelength_nm=600.0, reflection_factor=2.0, min_count=2)
    cut = average_surface([_sample(waves, mask)] * 2, wavelength_nm=600.0, reflection_factor=2.0, min_count=2,
                          edge_px=1)
    assert plain.rms_nm > 10.0 and cut.rms_nm < 1e-9
    assert cut.aperture.pixels < plain.aperture.pixels and not np.any(cut.mask & rim)
