"""The TMA model: diffraction-limited design, batoid's wavefront sign and orientation on our grid."""

from __future__ import annotations

import math

import batoid
import numpy as np
import pytest

from tma_helpers import camera_xy_mm, example, fit_noll
from wavestack.pipeline.telescope import AsBuiltErrors, HexapodPose, TmaModel

MARECHAL = 1.0 / 14.0


@pytest.fixture(scope="module")
def model():
    design, _ = example()
    return TmaModel(design)


def test_nominal_design_is_diffraction_limited_at_every_field_point(model):
    for field in model.design.field_points_deg:
        w = model.wavefront(field, HexapodPose())
        assert np.array_equal(np.isfinite(w), model.pupil_mask)
        rms = float(np.sqrt(np.nanmean(w ** 2)))  # piston removed by the model, tilt kept
        assert 0.0 < rms <= MARECHAL, (field, rms)


def test_pupil_is_an_off_axis_rounded_rectangle_long_along_x(model):
    mask = model.pupil_mask
    rows, cols = np.nonzero(mask)
    assert np.ptp(cols) + 1 == pytest.approx(model.design.pupil.size_mm[0] / model.design.pixel_mm, abs=1)
    assert np.ptp(rows) + 1 == pytest.approx(model.design.pupil.size_mm[1] / model.design.pixel_mm, abs=1)
    assert not mask[rows.min(), cols.min()]  # a rounded corner


def test_matches_batoid_wavefront_at_the_design_pose(model):
    design = model.design
    fx, fy = design.field_points_deg[-1]
    ours = model.wavefront((fx, fy), HexapodPose())
    theirs = batoid.wavefront(model.optic(HexapodPose()), math.radians(fx), math.radians(fy),
                              design.wavelength_nm * 1e-9, nx=242, sphereRadius=model.sphere_radius_mm * 1e-3,
                              reference="chief")
    # batoid's grid: 242 rays over 240 mm, 1 mm apart, row index = +y, centred on the pupil centre
    grid = np.ma.filled(theirs.array, np.nan)
    xx, yy = camera_xy_mm(design)
    ok = model.pupil_mask
    cols = np.round(xx[ok] / 1.0 + 121).astype(int)
    rows = np.round(yy[ok] / 1.0 + 121).astype(int)
    # our pixel centres sit half a pixel from batoid's ray grid: compare on the nearest rays
    sampled = grid[rows, cols]
    sampled -= np.nanmean(sampled)
    assert np.nanstd(sampled - ours[ok]) < 0.01 * np.nanstd(ours[ok]) + 1e-3


def _exit_jacobian(model, field, pose):
    """Transverse position on the reference sphere per camera mm (detector frame), shape (2, 2)."""
    optic = model.optic(pose)
    dir_cos = batoid.utils.fieldToDirCos(math.radians(field[0]), math.radians(field[1]))
    h = 0.01
    rays = batoid.RayVector.fromStop(np.array([0.0, h, 0.0]), np.array([0.0, 0.0, h]), optic=optic,
                                     wavelength=633e-9, dirCos=dir_cos)
    optic.trace(rays)
    radius = model.sphere_radius_mm * 1e-3
    target = rays.coordSys.shiftLocal(model._reference(tuple(field)) + [0.0, 0.0, radius])
    rays.toCoordSys(target)
    batoid.Sphere(-radius).intersect(rays)
    r = rays.r[:, :2]
    return np.column_stack([(r[1] - r[0]) / (h * 1e3), (r[2] - r[0]) / (h * 1e3)])


def _chief_image(model, field, pose):
    optic = model.optic(pose)
    dir_cos = batoid.utils.fieldToDirCos(math.radians(field[0]), math.radians(field[1]))
    ray = batoid.RayVector.fromStop(np.zeros(1), np.zeros(1), optic=optic, wavelength=633e-9, dirCos=dir_cos)
    optic.trace(ray)
    return ray.r[0]


@pytest.mark.parametrize("pose", [HexapodPose(v=0.005), HexapodPose(u=-0.004), HexapodPose(x=0.05)])
def test_mirror_tilt_gives_the_tilt_terms_of_the_expected_sign(model, pose):
    design = model.design
    field = design.field_points_deg[0]
    delta = (_chief_image(model, field, pose) - _chief_image(model, field, HexapodPose()))[:2]  # m
    jac = _exit_jacobian(model, field, HexapodPose())
    radius = model.sphere_radius_mm * 1e-3
    # batoid's reference sphere lies a radius R *beyond* the reference point (the beam diverges
    # there). A wave from an image displaced by delta reaches a sphere point at transverse
    # offset e (from the vertex) earlier by e.delta / R, and W = t0 - t leads: dW/d(e) = +delta / R.
    # Chained through the pupil mapping J (camera mm -> sphere), dW/d(camera) = J^T delta / R:
    expected = (jac.T @ delta) / radius / (design.wavelength_nm * 1e-9)
    norm_radius = float(np.hypot(*design.pupil.size_mm) / 2)
    expected_z2_z3 = expected * norm_radius / 2.0  # Noll Z2 = 2 x, Z3 = 2 y on the unit disk
    c = fit_noll(design, model.wavefront(field, pose) - model.wavefront(field, HexapodPose()))
    big = np.argmax(np.abs(expected_z2_z3))
    assert np.sign(c[1 + big]) == np.sign(expected_z2_z3[big])
    assert c[1 + big] == pytest.approx(expected_z2_z3[big], rel=0.1)


def _focus(model, field, pose):
    """Least-squares convergence point of the whole beam (detector frame, m)."""
    optic = model.optic(pose)
    rays = model._rays(optic, tuple(field))
    optic.trace(rays)
    d = rays.v / np.linalg.norm(rays.v, axis=1)[:, None]
    proj = np.eye(3)[None] - d[:, :, None] * d[:, None, :]
    return np.linalg.solve(proj.sum(0), np.einsum("nij,nj->i", proj, rays.r)), d.mean(0)


def test_despace_gives_defocus_of_the_paraxial_sign_and_size(model):
    design = model.design
    field = design.field_points_deg[0]
    pose = HexapodPose(z=0.02)
    p0, axis = _focus(model, field, HexapodPose())
    p1, _ = _focus(model, field, pose)
    shift = float((p1 - p0) @ axis)  # > 0: the focus moved downstream, beyond the interferometer
    jac = _exit_jacobian(model, field, HexapodPose())
    radius = model.sphere_radius_mm * 1e-3
    norm_radius = float(np.hypot(*design.pupil.size_mm) / 2)
    # a focus `shift` beyond the reference point: on batoid's sphere (a radius beyond the point) the
    # wave from the shifted focus lags by shift |e|^2 / (2 R^2): W = -shift |e|^2 / (2 R^2); |e|^2 =
    # |det J| |camera|^2 for a conformal pupil mapping; Noll Z4 = sqrt(3) (2 rho^2 - 1)
    curvature = -shift * abs(np.linalg.det(jac)) / (2 * radius ** 2) / (design.wavelength_nm * 1e-9)
    expected_z4 = curvature * norm_radius ** 2 / (2 * math.sqrt(3))
    c = fit_noll(design, model.wavefront(field, pose) - model.wavefront(field, HexapodPose()))
    assert abs(expected_z4) > 0.05  # the step is large enough to read
    assert np.sign(c[3]) == np.sign(expected_z4)
    assert c[3] == pytest.approx(expected_z4, rel=0.15)


def test_camera_grid_is_x_right_y_up(model):
    # a decentre along +y of the aligned mirror vs a decentre along +x: the dominant tilt
    # terms swap between Z3 (y) and Z2 (x), so rows carry y and columns x
    field = model.design.field_points_deg[0]
    base = model.wavefront(field, HexapodPose())
    cx = fit_noll(model.design, model.wavefront(field, HexapodPose(x=0.05)) - base)
    cy = fit_noll(model.design, model.wavefront(field, HexapodPose(y=0.05)) - base)
    assert abs(cx[1]) > 5 * abs(cx[2]) and abs(cy[2]) > 5 * abs(cy[1])


def test_as_built_errors_are_seeded_and_change_the_wavefront():
    design, errors = example()
    a = TmaModel(design, errors)
    b = TmaModel(design, errors)
    c = TmaModel(design, errors, seed=errors.seed + 1)
    field = design.field_points_deg[0]
    assert a.as_built == b.as_built and a.as_built != c.as_built
    assert design.aligned_mirror not in a.as_built
    wa, wc = a.wavefront(field, HexapodPose()), c.wavefront(field, HexapodPose())
    assert np.nanstd(wa - wc) > 1e-3
    with pytest.raises(ValueError, match="tilt_deg_rms"):
        AsBuiltErrors(tilt_deg_rms=-1.0)


def test_the_off_axis_beams_clear_every_mirror_and_the_image(model):
    # the point of an off-axis section: no mirror sits in another beam. In the y-z plane, at
    # every field point: M3's footprint lies below M1's, the incoming beam passes above M2,
    # and the M2 -> M3 and M1 -> M2 beams pass above the image where they cross its plane.
    design = model.design
    optic = model.optic(HexapodPose())
    z_m2 = design.mirror("M2").vertex_z_mm
    z_image = design.image_z_mm
    for field in design.field_points_deg:
        full = optic.traceFull(model._rays(optic, field))
        y = {name: full[name]["out"].toCoordSys(batoid.CoordSys()).r[:, 1] * 1e3 for name in full}
        slope_in = math.tan(math.radians(field[1]))  # incoming rays: y changes by -slope per +z
        assert y["M3"].max() + 20 < y["M1"].min()
        assert y["M2"].max() + 20 < y["M1"].min() - z_m2 * slope_in
        m2_to_m3_at_image = y["M3"] + (y["M2"] - y["M3"]) * z_image / z_m2
        assert y["Detector"].max() + 20 < m2_to_m3_at_image.min()


@pytest.mark.parametrize("mount", [HexapodPose(x=0.2, y=-0.1, z=0.15), HexapodPose(u=0.02), HexapodPose(v=-0.03)])
def test_a_mounting_error_is_undone_by_the_opposite_pose(mount):
    # a pure translation, or a rotation about one axis through the pivot, is undone exactly by its
    # opposite (a general pose is not: P(M(p)) leaves R_P t_M - t_M, the loop's job to remove)
    design, _ = example()
    model = TmaModel(design, mount=mount)
    field = design.field_points_deg[0]
    opposite = HexapodPose(*(-value for value in mount.as_tuple()))
    misaligned = model.wavefront(field, HexapodPose())
    undone = model.wavefront(field, opposite)
    nominal = TmaModel(design).wavefront(field, HexapodPose())
    assert np.nanstd(misaligned - nominal) > 1.0  # waves: far from aligned
    assert np.nanstd(undone - nominal) < 1e-6
