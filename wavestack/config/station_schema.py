"""The schemas of a station file's own tables and the checked station: ``[station]``, ``[outputs]``, :class:`StationConfig`.

Parsing lives in :mod:`wavestack.config.station`; the rules across tables in
:mod:`wavestack.config.station_rules`. Both import these classes from here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from wavestack.config.camera import CameraSettings, CameraSimulatorSettings
from wavestack.config.plc import PlcConfig
from wavestack.config.processing import ProcessingSettings
from wavestack.config.pzt import PiezoSettings, PiezoSimulatorSettings
from wavestack.config.schema import setting
from wavestack.config.shack_hartmann import ShackHartmannSettings
from wavestack.config.simulated_bench import BenchSimulatorSettings, LensletSimulatorSettings, OpticSimulatorSettings
from wavestack.config.surface import SurfaceSettings
from wavestack.pipeline.calibration import ReferenceCalibration

__all__ = ["OutputSettings", "StationConfig", "StationSettings"]


@dataclass(frozen=True)
class StationSettings:
    """``[station]``: the run as a whole."""

    kind: Literal["interferometer", "shack-hartmann"] = setting(
        "interferometer", doc="phase maps from fringes, or slopes from a lenslet array")
    wavelength_nm: float = setting(632.8, minimum=100.0, maximum=20000.0, doc="test wavelength, nm")
    frame_timeout_s: float = setting(2.0, minimum=0.01, maximum=60.0, doc="longest wait for a frame or set, s")
    max_result_age_s: float = setting(1.0, minimum=0.01, maximum=60.0,
                                      doc="an older result is stale and never forwarded, s")
    reconnect_max_s: float = setting(5.0, minimum=0.01, maximum=600.0, doc="longest reconnect back-off, s")
    set_ring_capacity: int = setting(2, minimum=1, maximum=64, doc="phase-shifted sets held for the pipeline")
    heap_release_s: float = setting(1.0, minimum=0.0, maximum=3600.0,
                                    doc="give freed heap memory back to the system at most this often, s (0: never)")
    max_processing_s: float = setting(60.0, minimum=0.01, maximum=3600.0,
                                      doc="longest a set's processing keeps the PLC heartbeat going, s; "
                                          "beyond it the heartbeat stops and the watchdog trips")


@dataclass(frozen=True)
class OutputSettings:
    """``[outputs]``: the removal command sent to the polishing PLC for each valid result.

    The command per Zernike term is ``gain * surface_nm`` for terms from ``first_term`` on (piston
    and tilts are alignment, not polishing), ``surface_nm = wavefront_waves * wavelength_nm *
    surface_factor`` (0.5 for a surface seen in reflection, double pass). It then passes the safety
    stage: clipped to +-``max_removal_nm``, changed by at most ``max_step_nm`` per update.
    """

    enabled: bool = setting(True, doc="send removal commands when a PLC is configured")
    gain: float = setting(0.5, minimum=0.0, maximum=1.0, doc="fraction of the measured error commanded")
    surface_factor: float = setting(0.5, minimum=0.01, maximum=10.0, doc="surface per wavefront")
    first_term: int = setting(4, minimum=1, maximum=231, doc="first Noll term commanded (4 = defocus)")
    max_removal_nm: float = setting(200.0, minimum=0.0, maximum=1e5, doc="drive limit per term, nm")
    max_step_nm: float = setting(50.0, minimum=1e-6, maximum=1e5, doc="largest change per update, nm")
    passes: int = setting(1, minimum=1, maximum=100)


@dataclass(frozen=True, eq=False)
class StationConfig:
    """A checked station configuration (every table parsed) and its source text."""

    source: str
    text: str
    station: StationSettings
    processing: ProcessingSettings
    camera: CameraSettings
    camera_simulator: CameraSimulatorSettings
    pzt: PiezoSettings | None
    pzt_simulator: PiezoSimulatorSettings | None
    plc: PlcConfig | None
    outputs: OutputSettings
    optic: OpticSimulatorSettings | None
    bench: BenchSimulatorSettings
    shack_hartmann: ShackHartmannSettings | None = None
    lenslets: LensletSimulatorSettings | None = None
    surface: SurfaceSettings = SurfaceSettings()
    calibration: ReferenceCalibration | None = None  # [processing] calibration, read and checked

    @property
    def phase_stepping(self) -> bool:
        """True for an interferometer stepping a piezo (triggered camera, phase-shifted sets)."""
        return self.station.kind == "interferometer" and self.processing.method == "psi"
