"""The hexapod pose rule (PI: U then V then W about axes moving with the platform) and the pivot."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fuzz import fuzz_settings
from tma_helpers import example
from wavestack.pipeline.telescope import HexapodPose, build_optic, pose_rotation, transform_point
from wavestack.pipeline.telescope.pose import rotation_x, rotation_y, rotation_z

angles = st.floats(-20.0, 20.0, allow_nan=False)


@fuzz_settings(200)
@given(angles, angles, angles)
def test_pose_rotation_is_u_then_v_then_w_about_moving_axes(u, v, w):
    r = pose_rotation(u, v, w)
    assert np.allclose(r @ r.T, np.eye(3), atol=1e-12) and np.isclose(np.linalg.det(r), 1.0)
    # intrinsic X, Y', Z'': the same as fixed axes in the order W, V, U
    assert np.allclose(r, rotation_x(u) @ rotation_y(v) @ rotation_z(w))


def test_the_order_matters_and_v_turns_about_the_axis_tilted_by_u():
    r = pose_rotation(30.0, 30.0, 0.0)
    assert not np.allclose(r, rotation_y(30.0) @ rotation_x(30.0), atol=1e-3)
    # after U, the V axis is the platform's y axis rotated by U: V turns about it
    moved_y_axis = rotation_x(30.0) @ [0.0, 1.0, 0.0]
    assert np.allclose(r @ [0.0, 1.0, 0.0], moved_y_axis)


@fuzz_settings(200)
@given(angles, angles, angles)
def test_a_pure_rotation_leaves_the_pivot_in_place(u, v, w):
    pivot = np.array([3.0, -2.0, 500.0])
    assert np.allclose(transform_point(pivot, HexapodPose(u=u, v=v, w=w), pivot), pivot, atol=1e-9)
    moved = transform_point(pivot, HexapodPose(x=0.1, y=-0.2, z=0.3, u=u, v=v, w=w), pivot)
    assert np.allclose(moved, pivot + [0.1, -0.2, 0.3], atol=1e-9)


@pytest.mark.parametrize("pivot", [None, (0.0, 40.0, 520.0)])
def test_batoid_perturbation_follows_the_pose_rule(pivot):
    design, _ = example()
    if pivot is not None:
        from dataclasses import replace
        design = replace(design, pivot_mm=pivot)
    pose = HexapodPose(0.2, -0.1, 0.05, 0.3, -0.4, 0.0)
    optic = build_optic(design, pose=pose)
    nominal = build_optic(design)
    name = design.aligned_mirror
    # a point fixed to the mirror, in its local frame, goes where transform_point says
    local = np.array([0.01, 0.02, 0.003])
    before = nominal[name].coordSys.origin + nominal[name].coordSys.rot @ local
    after = optic[name].coordSys.origin + optic[name].coordSys.rot @ local
    expected = transform_point(before * 1e3, pose, design.pivot()) * 1e-3
    assert np.allclose(after, expected, atol=1e-12)
    assert np.allclose(optic[name].coordSys.rot, pose.rotation() @ nominal[name].coordSys.rot)


def test_pose_checks_name_the_axis():
    with pytest.raises(ValueError, match="pose U"):
        HexapodPose(u=float("nan"))
    with pytest.raises(ValueError, match="6 values"):
        HexapodPose.from_sequence([1, 2, 3])
