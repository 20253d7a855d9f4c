"""The batoid optic of a TMA: the design, its seeded as-built errors, and the hexapod pose.

Built with batoid (Meyers et al., LSST's ray tracer, https://github.com/jmeyers314/batoid): each
mirror a ``batoid.Mirror`` of a ``batoid.Quadric`` (a ``batoid.Paraboloid`` for ``k = -1``, where
batoid's quadric intersection divides by ``1 + k``), a ``batoid.Detector`` plane at the image, and
a stop plane centred on the off-axis pupil so that ray grids start on the rounded rectangle.
Perturbations use batoid's own API: ``withGloballyRotatedOptic`` (about a global centre) then
``withGloballyShiftedOptic``, which together give ``p' = pivot + t + R (p - pivot)``.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import batoid
import numpy as np

from .design import TmaDesign
from .pose import HexapodPose, rotation_x, rotation_y

__all__ = ["AsBuiltErrors", "MirrorError", "build_optic", "draw_as_built"]

_LOG = logging.getLogger(__name__)
_MM = 1e-3


@dataclass(frozen=True)
class MirrorError:
    """A rigid-body error of one mirror: decentre/despace mm and tilts about x, y deg."""

    dx_mm: float = 0.0
    dy_mm: float = 0.0
    dz_mm: float = 0.0
    tilt_x_deg: float = 0.0
    tilt_y_deg: float = 0.0


@dataclass(frozen=True)
class AsBuiltErrors:
    """How far the as-built telescope may differ from the design (RMS per degree of freedom).

    The errors are rigid-body errors of every mirror but the aligned one, drawn once from a
    seeded normal distribution (:func:`draw_as_built`); the controller never sees them.

    Attributes
    ----------
    decentre_mm_rms, despace_mm_rms : float
        RMS of the x, y decentres and of the z despace, mm (>= 0).
    tilt_deg_rms : float
        RMS of the tilts about x and y, deg (>= 0).
    seed : int
        Seed of the draw.
    """

    decentre_mm_rms: float = 0.0
    despace_mm_rms: float = 0.0
    tilt_deg_rms: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("decentre_mm_rms", "despace_mm_rms", "tilt_deg_rms"):
            value = getattr(self, name)
            if not math.isfinite(value) or value < 0.0:
                raise ValueError(f"{name}: expected a finite value >= 0, got {value!r}")


def draw_as_built(design: TmaDesign, errors: AsBuiltErrors) -> dict[str, MirrorError]:
    """The seeded rigid-body error of each mirror but the aligned one (name -> error)."""
    rng = np.random.default_rng(errors.seed)
    drawn: dict[str, MirrorError] = {}
    for mirror in design.mirrors:
        if mirror.name == design.aligned_mirror:
            continue
        d = rng.standard_normal(5)
        drawn[mirror.name] = MirrorError(
            d[0] * errors.decentre_mm_rms, d[1] * errors.decentre_mm_rms, d[2] * errors.despace_mm_rms,
            d[3] * errors.tilt_deg_rms, d[4] * errors.tilt_deg_rms)
    return drawn


def _surface(radius_m: float, conic: float) -> batoid.Surface:
    if conic == -1.0:
        return batoid.Paraboloid(radius_m)
    return batoid.Quadric(radius_m, conic)


def build_optic(design: TmaDesign, as_built: dict[str, MirrorError] | None = None,
                pose: HexapodPose | None = None, mount: HexapodPose | None = None) -> batoid.CompoundOptic:
    """The batoid optic of the design with its as-built errors and the aligned mirror's pose.

    Parameters
    ----------
    design : TmaDesign
    as_built : dict of name -> MirrorError, optional
        Rigid-body errors about each mirror's vertex (tilt about x, then y, fixed axes).
    pose : HexapodPose, optional
        The hexapod pose of ``design.aligned_mirror`` about ``design.pivot()``.
    mount : HexapodPose, optional
        Where the aligned mirror sits on the platform at the home pose (its unknown mounting
        error, same rule about the same pivot), applied before ``pose``: ``p' = P(M(p))``.

    Returns
    -------
    batoid.CompoundOptic
        Named ``"TMA"``, items ``design.mirrors`` then ``"Detector"``; lengths in metres.
    """
    items = [batoid.Mirror(_surface(m.radius_mm * _MM, m.conic), name=m.name,
                           coordSys=batoid.CoordSys(origin=[0.0, 0.0, m.vertex_z_mm * _MM]))
             for m in design.mirrors]
    items.append(batoid.Detector(batoid.Plane(), name="Detector",
                                 coordSys=batoid.CoordSys(origin=[0.0, 0.0, design.image_z_mm * _MM])))
    cx, cy = design.pupil.centre_mm
    stop = batoid.Interface(batoid.Plane(), coordSys=batoid.CoordSys(
        origin=[cx * _MM, cy * _MM, design.stop_z_mm * _MM]))
    optic = batoid.CompoundOptic(items, name="TMA", stopSurface=stop, pupilSize=max(design.pupil.size_mm) * _MM,
                                 backDist=1.0, inMedium=batoid.ConstMedium(1.0))
    for name, err in (as_built or {}).items():
        vertex = [0.0, 0.0, design.mirror(name).vertex_z_mm * _MM]
        rot = rotation_y(err.tilt_y_deg) @ rotation_x(err.tilt_x_deg)
        optic = optic.withGloballyRotatedOptic(name, rot, rotCenter=vertex)
        optic = optic.withGloballyShiftedOptic(name, [err.dx_mm * _MM, err.dy_mm * _MM, err.dz_mm * _MM])
    pivot = np.asarray(design.pivot()) * _MM
    for step in (mount, pose):
        if step is not None and step != HexapodPose():
            optic = optic.withGloballyRotatedOptic(design.aligned_mirror, step.rotation(), rotCenter=pivot)
            optic = optic.withGloballyShiftedOptic(design.aligned_mirror, [step.x * _MM, step.y * _MM, step.z * _MM])
    return optic
