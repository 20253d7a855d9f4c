"""The simulated calibration ball of a station's ``[optic.ball]``: its seating and the truth a random ball test is judged by."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from wavestack.pipeline import build_fitter
from wavestack.simulators.optic import TestOptic

__all__ = ["ball_seating", "reference_truth_errors"]


def ball_seating(optic: Any) -> Callable[[int], None]:
    """``seat(k)`` for the random ball test: re-seat the simulated ball at a random orientation.

    Raises
    ------
    ValueError
        Not a simulated interferometer with ``[optic.ball]``.
    """
    if not isinstance(optic, TestOptic) or optic.settings.ball is None:
        raise ValueError("the random ball test needs a calibration ball: a simulated station with [optic.ball], "
                         "or a real one (the operator re-seats the ball)")

    def seat(index: int) -> None:
        optic.reseat_ball()

    return seat


def reference_truth_errors(optic: TestOptic, calibration: Any, wavelength_nm: float) -> dict[str, float]:
    """The answer against the simulated reference: RMS over the aperture of the error, of the stated uncertainty
    and of the truth, nm of wavefront, on the terms the test keeps (piston, tilt, power left out)."""
    fitter = build_fitter(calibration.mask, "circle", len(calibration.modes), pupil=calibration.pupil,
                          dtype=np.float64)
    reference = optic.truth(0.0).reference_waves
    true = fitter.fit(np.where(calibration.mask, 0.0 if reference is None else reference, np.nan)).coefficients
    keep = np.diag(calibration.reference_covariance) > 0
    eye = np.eye(len(keep))
    basis = np.stack([fitter.surface(eye[j]) for j in range(len(keep))], axis=-1)[calibration.mask]
    stated = np.sqrt(np.mean(np.einsum("pi,ij,pj->p", basis, calibration.reference_covariance, basis)))
    return {"reference_error_nm_rms": fitter.surface_rms(np.where(keep, calibration.reference - true, 0.0))
            * wavelength_nm,
            "reference_uncertainty_nm_rms": float(stated) * wavelength_nm,
            "reference_truth_nm_rms": fitter.surface_rms(np.where(keep, true, 0.0)) * wavelength_nm}
