"""TestOptic.wavefront (the truth map on a sub-grid) and TestOptic.frame (a frame without the truth map)."""

from __future__ import annotations

import tracemalloc
from dataclasses import replace

import numpy as np
import pytest

from wavestack.simulators.optic import ApertureShape, OpticSettings, TestOptic

_DRIFTING = OpticSettings(zernike_waves=(0.0, 0.0, 0.0, 0.3, 0.1, -0.2), drift_waves_per_s=(0.0, 0.0, 0.0, 0.002, 0.0, -0.001),
                          noise_rms=0.01, vibration_rms_rad=0.02, seed=3,
                          aperture=ApertureShape(centre_px=(30.3, 28.8), radius_px=27.0))


@pytest.mark.parametrize("step", [1, 2, 3])
def test_the_wavefront_on_a_grid_is_the_truth_map_sliced(step: int) -> None:
    optic = TestOptic(_DRIFTING, 96, 80)
    for t in (0.0, 2.5):
        np.testing.assert_array_equal(optic.wavefront(t, step), optic.truth(t).wavefront_waves[::step, ::step])


def test_the_wavefront_on_a_grid_allocates_grid_sized_arrays_only() -> None:
    optic = TestOptic(replace(_DRIFTING, aperture=ApertureShape(centre_px=(128.3, 126.8), radius_px=120.0)), 256, 256)
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        waves = optic.wavefront(7.0, 2)
        grid_peak = tracemalloc.get_traced_memory()[1] - before
        tracemalloc.reset_peak()
        full = optic.truth(7.0).wavefront_waves
        full_peak = tracemalloc.get_traced_memory()[1] - before - waves.nbytes
    finally:
        tracemalloc.stop()
    # one array of the grid's size (the drift term, the map added in place) and numpy's iteration
    # buffer for the strided input; a full-frame render (the map sliced afterwards) costs one array
    # of the frame's size, here four times the grid's
    assert grid_peak < 2 * waves.nbytes, grid_peak
    assert full_peak >= full.nbytes == 4 * waves.nbytes  # the measure sees what a full-frame render costs


@pytest.mark.parametrize("step", [0, -1, 1.5, True])
def test_a_bad_step_is_refused(step: object) -> None:
    with pytest.raises(ValueError, match="step"):
        TestOptic(_DRIFTING, 64, 64).wavefront(0.0, step)  # type: ignore[arg-type]


def test_frame_renders_what_interferogram_renders_with_the_same_facts() -> None:
    a, b = TestOptic(_DRIFTING, 64, 48), TestOptic(_DRIFTING, 64, 48)
    for t, shift in ((0.0, 0.0), (1.25, np.pi / 2), (3.0, np.pi)):
        pixels, truth = a.interferogram(t, shift)
        same, facts = b.frame(t, shift)
        np.testing.assert_array_equal(pixels, same)
        assert (facts.time_s, facts.phase_shift_rad, facts.vibration_rad, facts.carrier_cycles,
                facts.aperture_revision, facts.surface_revision) == \
               (truth.time_s, truth.phase_shift_rad, truth.vibration_rad, truth.carrier_cycles,
                truth.aperture_revision, truth.surface_revision)
