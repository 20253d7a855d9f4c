"""The design of an off-axis three-mirror anastigmat (TMA): mirrors, stop, pupil, field, wavelength.

A :class:`TmaDesign` is a plain frozen value (millimetres, degrees, nanometres) that
:mod:`wavestack.config.tma` reads from a TOML table and :mod:`~wavestack.pipeline.telescope.optic`
turns into a batoid optic. Coordinates are the telescope's global frame as batoid uses it for
its telescopes: light from the object travels towards ``-z``; the primary's vertex is at the
origin; ``x`` and ``y`` are the entrance pupil's axes seen from the object side (x right, y up).

The pupil is an off-axis section of a rotationally symmetric parent: a rounded rectangle centred
at ``pupil.centre_mm`` on the stop plane ``z = stop_z_mm``, long along ``x``: the Type II aperture
of the CSF-QCM method.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["PupilShape", "TmaDesign", "TmaMirror"]


def _finite(value: float, name: str, *, positive: bool = False) -> None:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
        raise ValueError(f"{name}: expected a finite number, got {value!r}")
    if positive and value <= 0.0:
        raise ValueError(f"{name}: expected > 0, got {value!r}")


@dataclass(frozen=True)
class TmaMirror:
    """One conic mirror of the parent (rotationally symmetric) design.

    Attributes
    ----------
    name : str
        ``"M1"``, ``"M2"``, ... (the name batoid's perturbation calls use).
    radius_mm : float
        Vertex radius of curvature, mm; batoid's sign: positive when the centre of curvature
        lies towards ``+z`` from the vertex (a concave primary facing the sky is positive).
    conic : float
        Conic constant ``k`` (0 sphere, -1 paraboloid, < -1 hyperboloid).
    vertex_z_mm : float
        Position of the vertex on the axis, mm.
    """

    name: str
    radius_mm: float
    conic: float
    vertex_z_mm: float

    def __post_init__(self) -> None:
        if not self.name or not self.name.isidentifier():
            raise ValueError(f"name: expected an identifier such as 'M2', got {self.name!r}")
        _finite(self.radius_mm, f"{self.name}.radius_mm")
        if self.radius_mm == 0.0:
            raise ValueError(f"{self.name}.radius_mm: expected a nonzero radius (a flat is not a TMA mirror)")
        _finite(self.conic, f"{self.name}.conic")
        _finite(self.vertex_z_mm, f"{self.name}.vertex_z_mm")


@dataclass(frozen=True)
class PupilShape:
    """The off-axis entrance pupil: a rounded rectangle on the stop plane.

    Attributes
    ----------
    centre_mm : (float, float)
        ``(x, y)`` of the centre on the stop plane, mm (the off-axis offset).
    size_mm : (float, float)
        Full width along ``x`` and full height along ``y``, mm (long side first for Type II).
    corner_radius_mm : float
        Radius of the rounded corners, ``0 <= r <= min(size) / 2`` mm.
    """

    centre_mm: tuple[float, float]
    size_mm: tuple[float, float]
    corner_radius_mm: float

    def __post_init__(self) -> None:
        for i, value in enumerate(self.centre_mm):
            _finite(value, f"pupil.centre_mm[{i}]")
        for i, value in enumerate(self.size_mm):
            _finite(value, f"pupil.size_mm[{i}]", positive=True)
        _finite(self.corner_radius_mm, "pupil.corner_radius_mm")
        if not 0.0 <= self.corner_radius_mm <= min(self.size_mm) / 2:
            raise ValueError(f"pupil.corner_radius_mm: expected 0 .. {min(self.size_mm) / 2:g} "
                             f"(half the short side), got {self.corner_radius_mm:g}")

    def contains(self, x_mm: ArrayLike, y_mm: ArrayLike) -> NDArray[np.bool_]:
        """Boolean mask of the points ``(x_mm, y_mm)`` (stop-plane mm, any shape) inside the pupil.

        Examples
        --------
        >>> PupilShape((0.0, 150.0), (240.0, 80.0), 20.0).contains([0.0, 119.0, 119.0], [150.0, 150.0, 189.0])
        array([ True,  True, False])
        """
        x_mm = np.asarray(x_mm, dtype=np.float64)
        y_mm = np.asarray(y_mm, dtype=np.float64)
        half_w, half_h = self.size_mm[0] / 2, self.size_mm[1] / 2
        r = self.corner_radius_mm
        dx = np.abs(x_mm - self.centre_mm[0]) - (half_w - r)
        dy = np.abs(y_mm - self.centre_mm[1]) - (half_h - r)
        inner = (dx <= 0) | (dy <= 0)
        return ((dx <= r) & (dy <= r)) & (inner | (dx * dx + dy * dy <= r * r))


@dataclass(frozen=True)
class TmaDesign:
    """An off-axis TMA: mirrors in the order light meets them, stop, pupil, image, field, wavelength.

    Attributes
    ----------
    mirrors : tuple of TmaMirror
        At least three, in the order light meets them.
    stop_z_mm : float
        The stop (entrance pupil) plane ``z``, mm.
    pupil : PupilShape
        The off-axis clear aperture on the stop plane.
    image_z_mm : float
        The focal plane ``z``, mm.
    field_points_deg : tuple of (float, float)
        Field angles ``(theta_x, theta_y)`` the interferometer visits, degrees.
    wavelength_nm : float
        Test wavelength, nm.
    aligned_mirror : str
        Name of the mirror on the hexapod (usually the secondary ``"M2"``).
    pivot_mm : (float, float, float) or None
        The hexapod's pivot point in global coordinates, mm; None: the aligned mirror's vertex.
    camera_shape : (int, int)
        ``(H, W)`` of the interferometer camera grid the wavefront is sampled on.
    pixel_mm : float
        Stop-plane millimetres per camera pixel (the pupil is centred on the grid).
    source : str
        Where the prescription comes from (paper, patent, or how it was derived).

    Examples
    --------
    >>> m = (TmaMirror("M1", 1600.0, -1.35, 0.0), TmaMirror("M2", 855.0, -6.26, 500.0),
    ...      TmaMirror("M3", 1836.3, -40.4, 0.0))
    >>> d = TmaDesign(m, 0.0, PupilShape((0.0, 150.0), (240.0, 80.0), 20.0), 326.2,
    ...               ((0.0, -0.6),), 632.8, "M2", None, (96, 256), 1.0, "derived")
    >>> d.pivot()
    (0.0, 0.0, 500.0)
    """

    mirrors: tuple[TmaMirror, ...]
    stop_z_mm: float
    pupil: PupilShape
    image_z_mm: float
    field_points_deg: tuple[tuple[float, float], ...]
    wavelength_nm: float
    aligned_mirror: str
    pivot_mm: tuple[float, float, float] | None
    camera_shape: tuple[int, int]
    pixel_mm: float
    source: str

    def __post_init__(self) -> None:
        names = [m.name for m in self.mirrors]
        if len(self.mirrors) < 3:
            raise ValueError(f"mirrors: expected at least 3 mirrors, got {len(self.mirrors)}")
        if len(set(names)) != len(names):
            raise ValueError(f"mirrors: expected distinct names, got {names}")
        if self.aligned_mirror not in names:
            raise ValueError(f"aligned_mirror: expected one of {names}, got {self.aligned_mirror!r}")
        _finite(self.stop_z_mm, "stop_z_mm")
        _finite(self.image_z_mm, "image_z_mm")
        _finite(self.wavelength_nm, "wavelength_nm", positive=True)
        _finite(self.pixel_mm, "pixel_mm", positive=True)
        if not self.field_points_deg:
            raise ValueError("field_points_deg: expected at least one field point")
        for i, (fx, fy) in enumerate(self.field_points_deg):
            _finite(fx, f"field_points_deg[{i}][0]")
            _finite(fy, f"field_points_deg[{i}][1]")
            if math.hypot(fx, fy) > 10.0:
                raise ValueError(f"field_points_deg[{i}]: expected within 10 deg of the axis, got {(fx, fy)}")
        if self.pivot_mm is not None:
            for i, value in enumerate(self.pivot_mm):
                _finite(value, f"pivot_mm[{i}]")
        rows, cols = self.camera_shape
        if not (8 <= rows <= 4096 and 8 <= cols <= 4096):
            raise ValueError(f"camera_shape: expected (H, W) each 8 .. 4096, got {self.camera_shape}")
        if self.pupil.size_mm[0] > cols * self.pixel_mm or self.pupil.size_mm[1] > rows * self.pixel_mm:
            raise ValueError(f"pixel_mm: the pupil {self.pupil.size_mm} mm does not fit a "
                             f"{self.camera_shape} grid of {self.pixel_mm:g} mm pixels")

    def mirror(self, name: str) -> TmaMirror:
        """The mirror called ``name`` (ValueError naming the known ones otherwise)."""
        for mirror in self.mirrors:
            if mirror.name == name:
                return mirror
        raise ValueError(f"mirror {name!r}: expected one of {[m.name for m in self.mirrors]}")

    def pivot(self) -> tuple[float, float, float]:
        """The hexapod pivot, mm: ``pivot_mm`` or the aligned mirror's vertex."""
        if self.pivot_mm is not None:
            return self.pivot_mm
        return (0.0, 0.0, self.mirror(self.aligned_mirror).vertex_z_mm)
