"""Configuration of the rotary mount's PI rotation stage: table ``[rotation_stage]`` (and ``[rotation_stage.simulator]``).

The same schema as ``[hexapod]`` (:mod:`wavestack.config.hexapod`: url, axes, soft limits, largest
step, timeouts), with exactly one axis, in degrees. ``url = "sim://"`` has the command start a
simulated GCS controller (``[rotation_stage.simulator]``, the schema of
:mod:`wavestack.config.hexapod_sim`) on loopback, coupled to the station's simulated part. The
packaged default (``rotation-stage.toml``) is that simulated stage.

Example::

    [rotation_stage]
    url = "tcp://192.168.0.30"          # a C-863 or C-884 with a rotation stage; port 50000
    axes = ["1"]
    soft_lower = [-10.0]
    soft_upper = [370.0]
    max_step = [360.0]
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from wavestack.config.hexapod import HexapodSettings, parse_hexapod_config
from wavestack.config.hexapod_sim import HexapodSimulatorSettings, parse_hexapod_sim_config
from wavestack.config.schema import ConfigError, load_toml

__all__ = ["DEFAULT_ROTATION_STAGE", "RotationStageConfig", "load_rotation_stage_config"]

#: The packaged simulated rotation stage.
DEFAULT_ROTATION_STAGE = Path(str(resources.files("wavestack.config") / "rotation-stage.toml"))


@dataclass(frozen=True)
class RotationStageConfig:
    """The rotation stage's driver settings and, for ``sim://``, its simulator's.

    Attributes
    ----------
    source : str
        The file read.
    stage : HexapodSettings
        One axis, degrees.
    simulator : HexapodSimulatorSettings or None
        ``[rotation_stage.simulator]`` when ``url = "sim://"``; None otherwise.
    """

    source: str
    stage: HexapodSettings
    simulator: HexapodSimulatorSettings | None

    @property
    def simulated(self) -> bool:
        """True when the command starts the simulated controller."""
        return self.simulator is not None


def load_rotation_stage_config(path: str | Path | None = None) -> RotationStageConfig:
    """Read ``[rotation_stage]`` from a TOML file (default: the packaged simulated stage).

    Raises
    ------
    ConfigError
        Any key error of the table, or not exactly one axis; the message names the file.
    """
    source = str(DEFAULT_ROTATION_STAGE if path is None else path)
    document = load_toml(source)
    stage = parse_hexapod_config(document, source=source, table="rotation_stage")
    if len(stage.axes) != 1:
        raise ConfigError(f"{source}: [rotation_stage] axes: expected one axis (the rotation, degrees), "
                          f"got {list(stage.axes)}")
    simulator = None
    if stage.url.startswith("sim://"):
        simulator = parse_hexapod_sim_config(document, source=source, table="rotation_stage")
    return RotationStageConfig(source=source, stage=stage, simulator=simulator)
