"""The simulated bench's per-frame truth: recomputed on request, equal to what was rendered."""

from __future__ import annotations

import dataclasses

import numpy as np

from wavestack.simulators.bench import FrameTruth
from wavestack.simulators.optic import ApertureShape, OpticSettings, TestOptic


def test_frame_truth_is_the_rendered_truth_until_the_aperture_changes() -> None:
    optic = TestOptic(OpticSettings(aperture=ApertureShape("circle", centre_px=(40.0, 30.0), radius_px=25.0),
                                    carrier_cycles=(4.0, 2.0), vibration_rms_rad=0.1, drift_waves_per_s=(0.0,) * 11,
                                    seed=2), 64, 80)
    _, rendered = optic.interferogram(0.7, 1.3)
    frame = FrameTruth(0.7, 13.0, 1.3, rendered.aperture_revision, optic, rendered.carrier_cycles,
                       rendered.vibration_rad)
    again = frame.optic
    for field in dataclasses.fields(rendered):
        a, b = getattr(rendered, field.name), getattr(again, field.name)
        assert np.array_equal(a, b, equal_nan=True) if isinstance(a, np.ndarray) else a == b, field.name
    optic.set_aperture(ApertureShape("circle", centre_px=(40.0, 30.0), radius_px=20.0))
    assert frame.optic is None  # unknown after the change, never the new aperture's map


def test_frame_truth_is_unknown_after_the_surface_is_polished() -> None:
    from wavestack.simulators import SurfaceSettings

    optic = TestOptic(OpticSettings(aperture=ApertureShape("circle", centre_px=(40.0, 30.0), radius_px=25.0),
                                    zernike_waves=(0.0,),
                                    surface=SurfaceSettings(zernike_nm=(0.0, 0.0, 0.0, 20.0), pixel_mm=0.5)),
                      64, 80)
    _, rendered = optic.interferogram(0.0, 0.0)
    frame = FrameTruth(0.0, None, 0.0, rendered.aperture_revision, optic, rendered.carrier_cycles,
                       rendered.vibration_rad, rendered.surface_revision)
    assert frame.optic is not None and np.array_equal(frame.optic.wavefront_waves, rendered.wavefront_waves,
                                                      equal_nan=True)
    optic.surface.apply_removal(np.full(optic.shape, 3.0))
    assert frame.optic is None  # the frame showed the surface before the removal: unknown now, never the new one
