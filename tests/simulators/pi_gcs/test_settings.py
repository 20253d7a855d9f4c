"""The simulator's settings refuse what no controller could be."""

from __future__ import annotations

import pytest

from wavestack.simulators.pi_gcs import HexapodSimSettings, SimPose


@pytest.mark.parametrize(("changes", "field"), [
    ({"axes": ("X", "X", "Z", "U", "V", "W")}, "axes"),
    ({"axes": ("X Y", "Z", "A", "U", "V", "W")}, "axes"),
    ({"low_limits": (0.0,) * 5}, "low_limits"),
    ({"high_limits": (-20.0,) * 6}, "limits of axis X"),
    ({"initial_position": (99.0, 0.0, 0.0, 0.0, 0.0, 0.0)}, "initial_position"),
    ({"velocity": 0.0}, "velocity"),
    ({"velocity": 30.0}, "velocity"),
    ({"pivot": (0.0, 0.0)}, "pivot"),
    ({"idn": "two\nlines"}, "idn"),
])
def test_bad_settings_are_refused_naming_the_field(changes: dict, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        HexapodSimSettings(**changes)


def test_the_start_position_is_zero_clipped_into_the_limits() -> None:
    settings = HexapodSimSettings(axes=("X",), low_limits=(5.0,), high_limits=(10.0,), pivot=None)
    assert settings.initial_position == (5.0,)


def test_a_pose_snapshot_names_a_missing_axis() -> None:
    pose = SimPose(("X", "Y"), (1.0, 2.0))
    with pytest.raises(KeyError, match="Z"):
        pose["Z"]
    assert pose.get("Z") == 0.0
