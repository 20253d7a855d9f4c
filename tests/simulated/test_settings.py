"""The configuration's simulator tables become the simulators' own settings, field by field, in one place."""

from __future__ import annotations

import dataclasses

import pytest

from wavestack.config import ConfigError, load_plc_config
from wavestack.config.camera import CameraSettings, CameraSimulatorSettings
from wavestack.config.hexapod_sim import HexapodSimulatorSettings
from wavestack.config.pzt import PiezoSimulatorSettings
from wavestack.config.simulated_bench import (
    ApertureShapeSettings,
    BenchSimulatorSettings,
    LensletSimulatorSettings,
    OpticSimulatorSettings,
    SurfaceSimulatorSettings,
)
from wavestack.simulated import as_simulator, camera_settings, hexapod_settings, piezo_device, plc_layout
from wavestack.simulators import SurfaceSettings
from wavestack.simulators.bench import PiezoCoupling
from wavestack.simulators.gige import GigESimSettings
from wavestack.simulators.optic import ApertureShape, OpticSettings
from wavestack.simulators.pi_gcs import HexapodSimSettings
from wavestack.simulators.spots import LensletArraySettings
from wavestack.simulators.u3v import U3VSimSettings

PAIRS = [(ApertureShapeSettings, ApertureShape), (SurfaceSimulatorSettings, SurfaceSettings),
         (OpticSimulatorSettings, OpticSettings), (BenchSimulatorSettings, PiezoCoupling),
         (LensletSimulatorSettings, LensletArraySettings)]


@pytest.mark.parametrize(("declared", "simulator"), PAIRS, ids=[p[0].__name__ for p in PAIRS])
def test_the_declared_settings_are_the_simulators_field_for_field_and_default_for_default(declared, simulator) -> None:
    assert [f.name for f in dataclasses.fields(declared)] == [f.name for f in dataclasses.fields(simulator)]
    assert as_simulator(declared(), simulator, source="t.toml", table="t") == simulator()


def test_a_nested_table_becomes_the_simulators_nested_settings() -> None:
    optic = OpticSimulatorSettings(aperture=ApertureShapeSettings(kind="annulus", radius_px=300.0, inner_radius_px=80.0),
                                   surface=SurfaceSimulatorSettings(zernike_nm=(0.0, 0.0, 0.0, 30.0)))
    built = as_simulator(optic, OpticSettings, source="t.toml", table="optic")
    assert isinstance(built.aperture, ApertureShape) and isinstance(built.surface, SurfaceSettings)
    assert (built.aperture.kind, built.surface.zernike_nm) == ("annulus", (0.0, 0.0, 0.0, 30.0))


def test_the_simulators_own_checks_name_the_file_and_the_nested_table() -> None:
    hole_outside = OpticSimulatorSettings(aperture=ApertureShapeSettings(kind="annulus", radius_px=100.0,
                                                                         inner_radius_px=30.0,
                                                                         obscuration_centre_px=(600.0, 512.0)))
    with pytest.raises(ConfigError, match=r"^bench.toml: \[optic.aperture\] obscuration_centre_px: the obscuration"):
        as_simulator(hole_outside, OpticSettings, source="bench.toml", table="optic")


def test_the_device_simulators_settings() -> None:
    assert camera_settings(CameraSettings(), CameraSimulatorSettings()) == U3VSimSettings(
        serial="WS-SIM-0001", width=1024, height=1024, pixel_format="Mono12", frame_rate_hz=30.0, zipped_xml=False)
    gige = camera_settings(CameraSettings(url="sim://gige"), CameraSimulatorSettings(serial="WS-SIM-0001-LONG-SERIAL"))
    assert isinstance(gige, GigESimSettings) and gige.serial == "WS-SIM-0001-LONG-SERIAL"[:16] and gige.width == 1024
    assert hexapod_settings(HexapodSimulatorSettings()) == HexapodSimSettings()
    assert hexapod_settings(HexapodSimulatorSettings(axes=("X", "Y"), low_limits=(-4.0, -4.0), high_limits=(4.0, 4.0))
                            ).pivot is None  # no rotation axes, no pivot
    with pytest.raises(ConfigError, match=r"^lab.toml: \[field_stage.simulator\] low_limits: expected 2"):
        hexapod_settings(HexapodSimulatorSettings(axes=("X", "Y")), source="lab.toml", table="field_stage")
    device = piezo_device(PiezoSimulatorSettings(prompt="*", vlimit_v=75.0))
    assert (device.personality.prompt, device.personality.decimals, device.vlimit_v) == ("*", 1, 75.0)
    config = load_plc_config(None)
    assert plc_layout(config).command_block == config.link.command_block
