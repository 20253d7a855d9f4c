"""The as-built TMA seen by the interferometer: wavefront maps on the camera grid per field and pose.

The camera grid maps the stop plane one to one (pixel ``(row, col)`` at ``x = (col - (W-1)/2) p``,
``y = ((H-1)/2 - row) p`` from the pupil centre, ``p = design.pixel_mm``): x right and y up on the
camera, as wavestack's Zernike bases use them (``wavestack.pipeline.zernike``), seen from the object
side. Pixels outside the rounded-rectangle pupil are NaN.

The wavefront is computed as ``batoid.wavefront`` does (trace, then the path to a reference sphere
of radius the exit-pupil distance placed a radius *beyond* the reference point, in waves,
``(t0 - t) / lambda``: positive where the wave leads), but about a *fixed* point: the design's
chief-ray image of the field point, where the bench's interferometer sits. A misaligned mirror
therefore shows as tilt (image motion) and defocus (image despace) besides the higher terms; the
piston is removed (mean zero over the pupil). Signs, pinned by tests/pipeline/telescope/test_model.py:
an image displaced by ``delta`` gives ``dW/d(camera) = J^T delta / R`` (``J`` the camera-to-sphere
mapping), and a focus beyond the reference point gives a negative Noll Z4. At the design pose the
map equals ``batoid.wavefront(..., reference='chief')`` (a test checks it).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from functools import lru_cache

import batoid
import numpy as np
from numpy.typing import NDArray

from .design import TmaDesign
from .optic import AsBuiltErrors, MirrorError, build_optic, draw_as_built
from .pose import HexapodPose

__all__ = ["TmaModel"]

_LOG = logging.getLogger(__name__)
_MM = 1e-3
FloatArray = NDArray[np.float64]


class TmaModel:
    """The telescope the bench renders: the design plus seeded as-built errors.

    Parameters
    ----------
    design : TmaDesign
    errors : AsBuiltErrors, optional
        How far the as-built telescope may differ from the design; None: a perfect build.
    seed : int, optional
        Overrides ``errors.seed`` when given.
    mount : HexapodPose, optional
        The aligned mirror's unknown mounting error on the platform (the misalignment an
        alignment run starts from; the hexapod pose near ``-mount`` realigns the telescope).

    Examples
    --------
    >>> from wavestack.pipeline.telescope import PupilShape, TmaDesign, TmaMirror
    >>> mirrors = (TmaMirror("M1", 1600.0, -1.350908, 0.0), TmaMirror("M2", 855.0204, -6.258799, 500.0),
    ...            TmaMirror("M3", 1836.3357, -40.39243, 0.0))
    >>> design = TmaDesign(mirrors, 0.0, PupilShape((0.0, 150.0), (240.0, 80.0), 20.0), 326.158,
    ...                    ((0.0, -0.6),), 632.8, "M2", None, (64, 128), 2.0, "config/tma-alignment.toml")
    >>> model = TmaModel(design)
    >>> w = model.wavefront((0.0, -0.6), HexapodPose())
    >>> w.shape, bool(np.nanstd(w) < 1 / 14), bool(np.nanstd(model.wavefront((0.0, -0.6), (0, 0, 0.1, 0, 0, 0))) > 0.2)
    ((64, 128), True, True)
    """

    def __init__(self, design: TmaDesign, errors: AsBuiltErrors | None = None, seed: int | None = None,
                 mount: HexapodPose | None = None) -> None:
        self.design = design
        self.mount = mount or HexapodPose()
        errors = errors or AsBuiltErrors()
        if seed is not None:
            errors = AsBuiltErrors(errors.decentre_mm_rms, errors.despace_mm_rms, errors.tilt_deg_rms, seed)
        self.as_built: dict[str, MirrorError] = draw_as_built(design, errors)
        self._design_optic = build_optic(design)
        self._wavelength_m = design.wavelength_nm * 1e-9
        self._mask, self._x_m, self._y_m = _camera_grid(design)
        self._sphere_m = _exit_pupil_distance(self._design_optic, design, self._wavelength_m)
        self._reference = lru_cache(maxsize=64)(self._reference_point)
        self._optic = lru_cache(maxsize=8)(self._posed_optic)

    @property
    def pupil_mask(self) -> NDArray[np.bool_]:
        """``(H, W)`` boolean mask of the pupil on the camera grid (a copy)."""
        return self._mask.copy()

    @property
    def sphere_radius_mm(self) -> float:
        """Radius of the reference sphere (exit pupil to image), mm."""
        return self._sphere_m / _MM

    def optic(self, pose: HexapodPose) -> batoid.CompoundOptic:
        """The as-built batoid optic with the aligned mirror at ``pose`` (cached)."""
        return self._optic(pose)

    def _posed_optic(self, pose: HexapodPose) -> batoid.CompoundOptic:
        return build_optic(self.design, self.as_built, pose, self.mount)

    def _rays(self, optic: batoid.CompoundOptic, field_deg: tuple[float, float]) -> batoid.RayVector:
        # fromStop takes coordinates on the stop surface, whose frame is centred on the pupil
        dir_cos = batoid.utils.fieldToDirCos(math.radians(field_deg[0]), math.radians(field_deg[1]))
        return batoid.RayVector.fromStop(self._x_m, self._y_m, optic=optic,
                                         wavelength=self._wavelength_m, dirCos=dir_cos)

    def _reference_point(self, field_deg: tuple[float, float]) -> FloatArray:
        """The design's chief-ray image point (detector coordinates, m) for a field point."""
        dir_cos = batoid.utils.fieldToDirCos(math.radians(field_deg[0]), math.radians(field_deg[1]))
        chief = batoid.RayVector.fromStop(np.zeros(1), np.zeros(1), optic=self._design_optic,
                                          wavelength=self._wavelength_m, dirCos=dir_cos)
        self._design_optic.trace(chief)
        return chief.r[0].copy()

    def wavefront(self, field_deg: Sequence[float], pose: HexapodPose | Sequence[float]) -> FloatArray:
        """The wavefront at a field point with the aligned mirror at ``pose``.

        Parameters
        ----------
        field_deg : (float, float)
            Field angle ``(theta_x, theta_y)``, degrees.
        pose : HexapodPose or (X, Y, Z, U, V, W)
            The hexapod pose of the aligned mirror (mm, deg) about the design's pivot.

        Returns
        -------
        ndarray, shape (H, W)
            Waves at the design wavelength, piston removed, NaN outside the pupil (and where a
            ray misses a mirror).
        """
        if not isinstance(pose, HexapodPose):
            pose = HexapodPose.from_sequence(pose)
        field = (float(field_deg[0]), float(field_deg[1]))
        if not all(math.isfinite(f) for f in field):
            raise ValueError(f"field_deg: expected finite angles, got {field_deg!r}")
        optic = self.optic(pose)
        rays = self._rays(optic, field)
        optic.trace(rays)
        values = _path_to_sphere(rays, self._reference(field), self._sphere_m) / self._wavelength_m
        bad = rays.vignetted | rays.failed | ~np.isfinite(values)
        values = np.where(bad, np.nan, values)
        values -= np.nanmean(values)
        out = np.full(self.design.camera_shape, np.nan)
        out[self._mask] = values
        return out


def _camera_grid(design: TmaDesign) -> tuple[NDArray[np.bool_], FloatArray, FloatArray]:
    """Pupil mask on the camera and the stop-plane offsets (m) of its pixels from the pupil centre."""
    rows, cols = design.camera_shape
    x_mm = (np.arange(cols) - (cols - 1) / 2) * design.pixel_mm
    y_mm = ((rows - 1) / 2 - np.arange(rows)) * design.pixel_mm
    xx, yy = np.meshgrid(x_mm, y_mm)
    cx, cy = design.pupil.centre_mm
    mask = design.pupil.contains(xx + cx, yy + cy)
    return mask, xx[mask] * _MM, yy[mask] * _MM


def _path_to_sphere(rays: batoid.RayVector, point: FloatArray, radius_m: float) -> FloatArray:
    """Optical path (m) of each ray to the reference sphere about ``point``, as batoid.wavefront."""
    target = rays.coordSys.shiftLocal(point + np.array([0.0, 0.0, radius_m]))
    rays.toCoordSys(target)
    batoid.Sphere(-radius_m).intersect(rays)
    return -rays.t  # (t0 - t): the piston t0 is removed by the caller


def _exit_pupil_distance(optic: batoid.CompoundOptic, design: TmaDesign, wavelength_m: float) -> float:
    """Distance from the exit pupil to the image (m): where chief rays of nearby fields cross."""
    fx, fy = design.field_points_deg[0]
    lines = []
    for dx in (0.0, 0.05):
        dir_cos = batoid.utils.fieldToDirCos(math.radians(fx + dx), math.radians(fy))
        ray = batoid.RayVector.fromStop(np.zeros(1), np.zeros(1), optic=optic,
                                        wavelength=wavelength_m, dirCos=dir_cos)
        optic.trace(ray)
        lines.append((ray.r[0].copy(), ray.v[0] / np.linalg.norm(ray.v[0])))
    (p1, d1), (p2, d2) = lines
    # closest approach of p1 + s d1 and p2 + u d2
    a = np.array([[d1 @ d1, -d1 @ d2], [d1 @ d2, -d2 @ d2]])
    s, _ = np.linalg.solve(a, np.array([(p2 - p1) @ d1, (p2 - p1) @ d2]))
    distance = float(abs(s))
    if not math.isfinite(distance) or distance <= 0.0:
        raise ValueError("design: the exit pupil could not be located from the chief rays")
    return distance
