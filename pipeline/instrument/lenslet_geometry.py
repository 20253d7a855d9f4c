"""Where the lenslets are, what a flat wavefront's spots look like, and which lenslets count.

Built once per frame shape from a :class:`~.sensor_setup.ShackHartmannSetup` and a reference
frame (a flat wavefront's spots, or the stream's first frame), :func:`lenslet_geometry` gives the
processor everything that does not change from frame to frame:

1. **the lattice**, placed as the setup says (:mod:`.sensor_setup`): the configured array, or
   the lattice :func:`~wavestack.pipeline.shack_hartmann.detect_lattice` finds in the reference
   frame. With ``lattice = "auto"`` and a configured array, the kind is the one the reference
   frame's spots lie on, and the configured array of that kind must explain them: of the spots
   over the array, at least 90 % within a quarter pitch of a configured lenslet (the bound
   :func:`detect_lattice` itself applies to a fitted lattice); a frame whose spots lie on
   neither kind, or on another array, is refused with the reason.
2. **the reference**: the lenslet centres, or the reference frame's spot centroids (only its lit
   lenslets, by the one rule :func:`~wavestack.pipeline.shack_hartmann.lit_lenslets`).
3. **the pupil lenslets**: those whose whole cell (square or hexagon,
   :meth:`~wavestack.pipeline.shack_hartmann.LensletLattice.cell_vertices`) lies inside the
   pupil disk, since a lenslet cut by the disk's edge reports the mean slope over its lit part
   only. The disk is configured, or the one the reference frame's lit lenslets cover.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
import scipy.spatial
from numpy.typing import NDArray

from ..shack_hartmann import Centroider, LatticeKind, LensletLattice, detect_lattice, lit_lenslets
from ..shack_hartmann.lit import TYPICAL_SPOT_PERCENTILE
from .sensor_setup import ShackHartmannSetup, tilt_is_measured

logger = logging.getLogger(__name__)

_PITCH_AGREEMENT = 0.2  # a found pitch and the described one may differ by this fraction (defocus)
_ON_SITE = 0.25  # a spot within this fraction of the pitch of a configured lenslet lies on it
_ON_ARRAY = 0.9  # ... for at least this fraction of the spots over the configured array


@dataclass(frozen=True, eq=False)
class LensletGeometry:
    """Everything that depends only on the setup, the frame shape and the reference frame.

    Attributes
    ----------
    frame_shape : (int, int)
    lattice : LensletLattice
        The lenslets considered, L of them.
    centroider : Centroider
        Built for ``lattice`` on ``frame_shape``, usable where ``in_pupil``.
    reference_px : ndarray, shape (L, 2)
        Spot positions ``(col, row)`` of a flat wavefront, pixels (NaN where none).
    pupil_px : (float, float, float)
        ``(col, row, radius)`` of the Zernike disk, pixels.
    in_pupil : ndarray of bool, shape (L,)
        The lenslets that count: whole cell inside the disk, with a reference spot.
    tilt_measured : bool
        False when the lattice sits on the frame's own spots against the ideal centres.
    typical_spot : float
        The reference frame's typical full spot (:data:`~wavestack.pipeline.shack_hartmann.lit.TYPICAL_SPOT_PERCENTILE`
        of its valid spots' thresholded intensities), counts; 0 when it has none.
    """

    frame_shape: tuple[int, int]
    lattice: LensletLattice
    centroider: Centroider
    reference_px: NDArray[np.float64]
    pupil_px: tuple[float, float, float]
    in_pupil: NDArray[np.bool_]
    tilt_measured: bool
    typical_spot: float


def lenslet_geometry(setup: ShackHartmannSetup, frame_shape: tuple[int, int], reference_frame: NDArray
                     ) -> LensletGeometry:
    """The lattice, reference and pupil lenslets for frames of ``frame_shape`` (module notes).

    Parameters
    ----------
    setup : ShackHartmannSetup
    frame_shape : (int, int)
        ``(rows, cols)`` of the frames.
    reference_frame : ndarray, shape ``frame_shape``
        A flat wavefront's spots, or the first frame of the stream.

    Returns
    -------
    LensletGeometry

    Raises
    ------
    ValueError
        One line with the reason: no lattice in the reference frame, a lattice that disagrees
        with the configured array, lenslet windows outside the frame, no lenslet inside the
        pupil, no reference spot.
    """
    if tuple(reference_frame.shape) != tuple(frame_shape):
        raise ValueError(f"reference frame of shape {reference_frame.shape}; expected the frames' {frame_shape}")
    if setup.placed_on_spots:
        lattice = _placed_on_spots(setup, reference_frame)
    else:
        kind = _detected_kind(setup, reference_frame) if setup.lattice == "auto" else setup.lattice
        lattice = configured_lattice(setup, kind, frame_shape)
    lattice.check_fits(frame_shape)
    options = {"threshold": setup.centroid_threshold, "min_intensity": setup.min_intensity}
    seen = Centroider.build(lattice, frame_shape, **options).measure(reference_frame)
    lit_in_reference = lit_lenslets(seen.intensity, seen.valid, setup.lit_fraction)
    if setup.reference == "frame":
        if not lit_in_reference.any():
            raise ValueError("no spots in the reference frame's lenslet windows; expected a Shack-Hartmann frame")
        reference = np.where(lit_in_reference[:, None], seen.centroids, np.nan)
    else:
        reference = lattice.centres()
    pupil = setup.pupil_px or _covered_disk(lattice, lit_in_reference)
    in_pupil = cells_inside(lattice, pupil) & np.isfinite(reference).all(axis=1)
    if not in_pupil.any():
        raise ValueError(f"no lenslet of the {lattice.kind} lattice (pitch {lattice.pitch_px:.2f} px) lies inside "
                         f"the pupil circle centred at ({pupil[0]:g}, {pupil[1]:g}) of radius {pupil[2]:g} px")
    centroider = Centroider.build(lattice, frame_shape, mask=in_pupil, **options)
    logger.info("Shack-Hartmann geometry: %s lattice of %d lenslets, pitch %.3f px at %.2f deg, %d in the pupil",
                lattice.kind, lattice.count, lattice.pitch_px, lattice.orientation_deg, int(in_pupil.sum()))
    typical = float(np.percentile(seen.intensity[seen.valid], TYPICAL_SPOT_PERCENTILE)) if seen.valid.any() else 0.0
    return LensletGeometry(tuple(frame_shape), lattice, centroider, reference, tuple(map(float, pupil)), in_pupil,
                           tilt_is_measured(setup), typical)


def configured_lattice(setup: ShackHartmannSetup, kind: LatticeKind, frame_shape: tuple[int, int]) -> LensletLattice:
    """The configured array of ``kind``: ``grid_shape`` lenslets, or the most rows and columns whose cells
    all lie in the frame (columns from the first row, and the second on a hexagonal array; then as
    many rows as hold them all).

    Raises
    ------
    ValueError
        If no whole lenslet cell fits in the frame.
    """
    assert setup.pitch_px is not None  # required with offset_px (ShackHartmannSetup)
    first = setup.first_centre_px
    if setup.grid_shape is not None:
        return LensletLattice.array(kind, setup.pitch_px, setup.grid_shape, first_centre_px=first,
                                    orientation_deg=setup.orientation_deg)
    reach = int(2 * math.hypot(*frame_shape) / setup.pitch_px) + 2
    candidates = LensletLattice.array(kind, setup.pitch_px, (reach, reach), first_centre_px=first,
                                      orientation_deg=setup.orientation_deg)
    corners = candidates.centres()[:, None, :] + candidates.cell_vertices()[None]
    # pixel centres are integers: the frame spans [-0.5, size - 0.5] along each axis
    fits = np.all((corners >= -0.5) & (corners <= np.array(frame_shape[::-1]) - 0.5), axis=(1, 2))
    fits = fits.reshape(reach, reach)
    cols = int(np.argmin(np.append(fits[: 2 if kind == "hexagonal" else 1].all(axis=0), False)))
    rows = int(np.argmin(np.append(fits[:, :cols].all(axis=1), False))) if cols else 0
    if rows < 1:
        raise ValueError(f"no whole lenslet of pitch {setup.pitch_px} px from {setup.offset_px} fits in a "
                         f"{frame_shape} frame")
    return LensletLattice.array(kind, setup.pitch_px, (rows, cols), first_centre_px=first,
                                orientation_deg=setup.orientation_deg)


def cells_inside(lattice: LensletLattice, pupil: tuple[float, float, float]) -> NDArray[np.bool_]:
    """Lenslets whose whole cell lies inside the disk ``(col, row, radius)``: its farthest corner does."""
    cx, cy, radius = pupil
    corners = lattice.centres()[:, None, :] + lattice.cell_vertices()[None] - np.array([cx, cy])
    return np.hypot(corners[..., 0], corners[..., 1]).max(axis=1) <= radius


def _covered_disk(lattice: LensletLattice, lit: NDArray[np.bool_]) -> tuple[float, float, float]:
    """The disk about the lit lenslets' centroid that holds their whole cells."""
    if not lit.any():
        raise ValueError("no lit lenslet in the reference frame to place the pupil on; expected spots, or pupil_px")
    centres = lattice.centres()[lit]
    cx, cy = centres.mean(axis=0)
    corners = centres[:, None, :] + lattice.cell_vertices()[None] - np.array([cx, cy])
    return float(cx), float(cy), float(np.hypot(corners[..., 0], corners[..., 1]).max())


def _found(reference_frame: NDArray) -> LensletLattice:
    try:
        return detect_lattice(reference_frame)
    except ValueError as error:
        raise ValueError(str(error).removeprefix("frame: ")) from None


def _placed_on_spots(setup: ShackHartmannSetup, reference_frame: NDArray) -> LensletLattice:
    """The lattice found in the reference frame; at the described pitch on its spots for an ideal reference."""
    found = _found(reference_frame)
    if setup.lattice != "auto" and found.kind != setup.lattice:
        raise ValueError(f"the spots lie on a {found.kind} lattice; expected the configured {setup.lattice} one")
    if setup.pitch_px is not None and abs(found.pitch_px / setup.pitch_px - 1.0) > _PITCH_AGREEMENT:
        raise ValueError(f"the spots are {found.pitch_px:.2f} px apart; the described pitch is {setup.pitch_px:.2f} px "
                         f"(expected within {_PITCH_AGREEMENT:.0%})")
    if setup.reference == "frame":
        return found
    assert setup.pitch_px is not None  # required with an ideal reference (ShackHartmannSetup)
    basis = np.asarray(found.basis_px) * (setup.pitch_px / found.pitch_px)
    spots = Centroider.build(found, reference_frame.shape).measure(reference_frame)
    used = spots.valid
    # the origin that puts the described lattice on the spots in the least-squares sense (the mean tilt)
    origin = np.mean(spots.centroids[used] - found.sites[used] @ basis, axis=0)
    return LensletLattice(found.kind, (tuple(basis[0]), tuple(basis[1])), tuple(origin), found.sites)


def _detected_kind(setup: ShackHartmannSetup, reference_frame: NDArray) -> LatticeKind:
    """The kind the reference frame's spots lie on, checked against the configured array of that kind."""
    found = _found(reference_frame)
    configured = configured_lattice(setup, found.kind, reference_frame.shape)
    spots = Centroider.build(found, reference_frame.shape).measure(reference_frame)
    points = spots.centroids[spots.valid]
    distance, _ = scipy.spatial.cKDTree(configured.centres()).query(points)
    pitch = configured.pitch_px
    over = distance <= pitch  # spots over the configured array
    on_site = distance <= _ON_SITE * pitch
    described = (f"the reference frame's spots lie on a {found.kind} lattice of pitch {found.pitch_px:.2f} px at "
                 f"{found.orientation_deg:.2f} deg")
    if not over.any() or on_site.sum() < _ON_ARRAY * over.sum():
        raise ValueError(f"{described}; {int(on_site.sum())} of the {int(over.sum())} spots over the configured "
                         f"{found.kind} array (pitch_px, orientation_deg, offset_px) lie within {_ON_SITE} pitch of "
                         f"its lenslets; expected at least {_ON_ARRAY:.0%}")
    logger.info("lattice = 'auto': %s", described)
    return found.kind
