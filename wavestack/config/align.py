"""Configuration of the alignment loop and its simulated bench: table ``[align]``.

``[align]`` holds the loop's settings (:class:`AlignSettings`) and, in ``[align.simulator]``, the
unknown misalignment the simulated bench starts from (:class:`AlignBenchSettings`). The telescope
is ``[tma]`` (:mod:`wavestack.config.tma`), the hexapod ``[hexapod]`` and the field stage
``[field_stage]`` (:mod:`wavestack.config.hexapod`, with their ``.simulator`` tables). Example:
``wavestack/config/tma-alignment.toml`` (shipped in the package), which ``wavestack align`` runs by default.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wavestack.config.hexapod import HexapodSettings, parse_hexapod_config
from wavestack.config.hexapod_sim import HexapodSimulatorSettings, parse_hexapod_sim_config
from wavestack.config.schema import ConfigError, parse_section, parse_toml, read_config_text, setting
from wavestack.config.tma import parse_tma_config
from wavestack.pipeline.telescope import AsBuiltErrors, TmaDesign

__all__ = ["AlignBenchSettings", "AlignConfig", "AlignSettings", "load_align_config", "parse_align_config"]

DEFAULT_CONFIG = Path(__file__).resolve().parent / "tma-alignment.toml"


@dataclass(frozen=True)
class AlignBenchSettings:
    """``[align.simulator]``: the simulated bench's unknown mount misalignment (uniform, seeded)."""

    decentre_mm: float = setting(0.3, minimum=0.0, maximum=5.0, doc="X, Y drawn in +-decentre_mm")
    despace_mm: float = setting(0.3, minimum=0.0, maximum=5.0, doc="Z drawn in +-despace_mm")
    tilt_deg: float = setting(0.03, minimum=0.0, maximum=0.5, doc="U, V drawn in +-tilt_deg")
    seed: int = setting(1, minimum=0, doc="seed of the draw")


@dataclass(frozen=True)
class AlignSettings:
    """``[align]``: the loop."""

    target_rms_waves: float = setting(1 / 14, minimum=0.0, maximum=10.0, doc="stop at this RMS at every field point")
    max_iterations: int = setting(5, minimum=1, maximum=100, doc="most corrections")
    gain: float = setting(0.9, minimum=0.01, maximum=1.0, doc="fraction of the estimate applied per iteration")
    rcond: float = setting(1e-3, minimum=1e-12, maximum=0.5, doc="relative singular-value threshold")
    min_improvement: float = setting(0.0, minimum=0.0, maximum=0.99, doc="fraction the worst RMS must drop by")
    max_noll: int = setting(22, minimum=4, maximum=66, doc="highest Noll term fitted")
    steps: tuple[float, ...] = setting((0.01, 0.01, 0.01, 0.001, 0.001), minimum=1e-9, maximum=1.0,
                                       doc="finite-difference half steps X Y Z mm, U V deg")
    scales: tuple[float, ...] = setting((0.1, 0.1, 0.1, 0.01, 0.01), minimum=1e-9, maximum=100.0,
                                        doc="column normalisation X Y Z mm, U V deg")
    readback_tolerance: tuple[float, ...] = setting((1e-3, 1e-3, 1e-3, 1e-4, 1e-4), minimum=0.0, maximum=1.0,
                                                    doc="largest read-back difference X Y Z mm, U V deg")
    field_stage_mm_per_deg: float = setting(10.0, minimum=1e-3, maximum=1e3,
                                            doc="field stage travel (axes 1, 2) per degree of field")
    simulated: bool = setting(True, doc="start the simulated bench (hexapod, field stage, telescope); false: a "
                                        "real bench at [hexapod] url, [field_stage] url, and [align] station")
    station: str | None = setting(None, doc="station TOML measuring through the camera (relative to this file); "
                                            "absent: the model's wavefront maps")
    averaged: int = setting(3, minimum=1, maximum=100, doc="valid station maps averaged per field point")
    measure_timeout_s: float = setting(30.0, minimum=0.1, maximum=600.0, doc="longest wait for a field point's "
                                                                             "station maps, s (then refused)")
    settle_s: float = setting(0.0, minimum=0.0, maximum=60.0, doc="maps count only if exposed this long after the "
                                                                  "stage and hexapod reported on target, s (station "
                                                                  "measurements; a real platform rings)")
    edge_px: int = setting(2, minimum=0, maximum=20, doc="pupil rim pixels left out of the fixed aperture "
                                                         "(station measurements)")
    fit_method: str = setting("csf-qcm", choices=("csf-qcm", "circle", "qr"),
                              doc="the fitter of the terms, model and measurement alike (the pipeline's)")
    null_tilt: bool = setting(True, doc="the interferometer's reference takes out the tilt at each field point "
                                        "(added back from its setting; station measurements)")
    simulator: AlignBenchSettings = setting(AlignBenchSettings(), doc="[align.simulator]")


@dataclass(frozen=True)
class AlignConfig:
    """Everything ``wavestack align`` needs from one file."""

    source: str
    text: str
    align: AlignSettings
    design: TmaDesign
    as_built: AsBuiltErrors
    hexapod: HexapodSettings
    field_stage: HexapodSettings
    hexapod_simulator: HexapodSimulatorSettings
    field_stage_simulator: HexapodSimulatorSettings

    def station_path(self) -> Path | None:
        """``[align] station`` relative to this file's folder (None when absent)."""
        if self.align.station is None:
            return None
        return (Path(self.source).resolve().parent / self.align.station).resolve()


def parse_align_config(document: Mapping[str, Any], *, source: str, text: str = "") -> AlignConfig:
    """Build the alignment configuration from a parsed TOML document.

    Raises
    ------
    ConfigError
        A missing table, any key error, or tuples of the wrong length (five: X Y Z U V).
    """
    table = document.get("align", {})
    if not isinstance(table, Mapping):
        raise ConfigError(f"{source}: [align] must be a table")
    settings = parse_section(AlignSettings, table, source=source, section="align")
    for key in ("steps", "scales", "readback_tolerance"):
        if len(getattr(settings, key)) != 5:
            raise ConfigError(f"{source}: [align] {key}: expected 5 values (X Y Z U V), got "
                              f"{len(getattr(settings, key))}")
    design, errors = parse_tma_config(document, source=source)
    hexapod = parse_hexapod_config(document, source=source, table="hexapod")
    stage = parse_hexapod_config(document, source=source, table="field_stage")
    missing = [a for a in ("X", "Y", "Z", "U", "V") if a not in hexapod.axes]
    if missing:
        raise ConfigError(f"{source}: [hexapod] axes: expected X Y Z U V among them, missing {missing}")
    if len(stage.axes) != 2:
        raise ConfigError(f"{source}: [field_stage] axes: expected 2 axes (field x, field y), got {list(stage.axes)}")
    return AlignConfig(source, text, settings, design, errors, hexapod, stage,
                       parse_hexapod_sim_config(document, source=source, table="hexapod"),
                       parse_hexapod_sim_config(document, source=source, table="field_stage"))


def load_align_config(path: str | Path | None = None) -> AlignConfig:
    """Read a file (default: the simulated alignment bench shipped in the package)."""
    path = Path(path) if path is not None else DEFAULT_CONFIG
    text = read_config_text(path)
    return parse_align_config(parse_toml(text, str(path)), source=str(path), text=text)
