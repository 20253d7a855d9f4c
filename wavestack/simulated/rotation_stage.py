"""Start the simulated rotation stage of a ``url = "sim://"`` stage file and couple it to the station's part.

A simulated PI GCS controller with the file's one rotary axis on loopback; the coupling turns the
station's simulated test optic (:meth:`~wavestack.simulators.optic.TestOptic.rotate_part`) to the
controller's true position, called once the stage is on target. The simulator keeps the truth, so
:meth:`SimulatedRotationStage.truth_errors` judges a calibration against the optic's part and
reference.
"""

from __future__ import annotations

from contextlib import ExitStack
from typing import Any

import numpy as np

from wavestack.config.rotation_stage import RotationStageConfig
from wavestack.pipeline import build_fitter
from wavestack.pipeline.calibration import rotate_coefficients
from wavestack.simulated.settings import hexapod_settings
from wavestack.simulators.optic import TestOptic
from wavestack.simulators.pi_gcs import HexapodSimulator

__all__ = ["SimulatedRotationStage", "start_rotation_stage"]


class SimulatedRotationStage:
    """The simulated controller, its URL and the coupling to the station's part (module notes).

    Parameters
    ----------
    config : RotationStageConfig
        A simulated stage (``config.simulator`` set).
    optic : TestOptic
        The station's simulated test optic.
    """

    def __init__(self, config: RotationStageConfig, optic: Any) -> None:
        if config.simulator is None or not isinstance(optic, TestOptic):
            raise ValueError(f"{config.source}: a simulated rotation stage turns a simulated interferometer's "
                             "part; expected url = 'sim://' and a station with a simulated camera")
        self.simulator = HexapodSimulator(hexapod_settings(config.simulator, source=config.source,
                                                           table="rotation_stage"))
        self.optic = optic
        self.axis = config.stage.axes[0]

    @property
    def url(self) -> str:
        """Where the driver connects (once started)."""
        return f"tcp://127.0.0.1:{self.simulator.port}"

    def turn_part(self) -> None:
        """Put the part at the controller's true angle (the calibration's ``on_arrival``)."""
        self.optic.rotate_part(self.simulator.pose[self.axis])

    def truth_errors(self, calibration: Any, wavelength_nm: float) -> dict[str, float]:
        """RMS over the calibration's aperture of (answer - truth), nm of wavefront, on the terms it separates.

        The truth is the optic's part (in its own frame, at angle 0) and its reference, fitted with
        the calibration's basis on its aperture; piston, tilt and the unresolved terms are left out
        of both sides.
        """
        truth = self.optic.truth(0.0)
        mask = calibration.mask
        fitter = build_fitter(mask, "circle", len(calibration.modes), pupil=calibration.pupil, dtype=np.float64)
        reference_map = np.zeros(mask.shape) if truth.reference_waves is None else truth.reference_waves
        seen = fitter.fit(np.where(mask, truth.wavefront_waves - reference_map, np.nan)).coefficients
        # the answer's part is the part as it sat at the start angle; the optic sits at its last angle
        start = calibration.settings.start_deg
        part = rotate_coefficients(calibration.modes, seen, np.deg2rad(start - truth.rotation_deg))
        reference = fitter.fit(np.where(mask, reference_map, np.nan)).coefficients
        keep = calibration.solution.resolved
        errors = {}
        for name, answer, true in (("part", calibration.solution.part, part),
                                   ("reference", calibration.solution.reference, reference)):
            errors[f"{name}_error_nm_rms"] = fitter.surface_rms(np.where(keep, answer - true, 0.0)) * wavelength_nm
            errors[f"{name}_truth_nm_rms"] = fitter.surface_rms(np.where(keep, true, 0.0)) * wavelength_nm
        return errors


def start_rotation_stage(config: RotationStageConfig, optic: Any, stack: ExitStack) -> SimulatedRotationStage:
    """:class:`SimulatedRotationStage` started; ``stack`` stops it."""
    stage = SimulatedRotationStage(config, optic)
    stack.enter_context(stage.simulator)
    return stage
