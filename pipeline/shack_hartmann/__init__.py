"""Shack-Hartmann spots to wavefront slopes: lenslet grid or lattice, centroiding, slope conversion.

A Shack-Hartmann sensor puts an array of lenslets (pitch ``p`` pixels on the camera, square or
hexagonal) in a pupil plane; each lenslet focuses its part of the beam to a spot on the
camera, and the spot moves by ``f * grad W`` when the wavefront ``W`` tilts over the lenslet
(``f`` the lenslet focal length). This package

1. describes the lenslets on the camera: an axis-aligned square grid (:class:`LensletGrid`,
   found by :func:`detect_grid`), or a square or hexagonal lattice at any orientation
   (:class:`LensletLattice`: two basis vectors, an origin and the lenslets used, found by
   :func:`detect_lattice`); both detections refuse, with the reason, spots that do not lie
   on the lattice they fit;
2. measures the spot centres by a thresholded centre of gravity, all lenslets in one
   vectorised pass, with everything that depends only on the grid precomputed once
   (:class:`Centroider`, :func:`centroid_spots`); frames of any real dtype and memory layout
   enter through :func:`camera_frame`;
3. turns spot displacements into wavefront slopes (:func:`slopes`) and re-expresses them in
   other units (:func:`convert_slopes`, :func:`slopes_in_waves_per_radius`);
4. reconstructs the wavefront: modal (:class:`ModalReconstructor`, from the lenslet centres
   and slopes of any lattice) or zonal (Southwell, square grids only).

The modules: :mod:`.grid` (the square grid), :mod:`.grid_detection` (finding it),
:mod:`.lattice` and :mod:`.lattice_detection` (any lattice, and finding it),
:mod:`.centroids` (spot centres), :mod:`.lit` (which lenslets count as lit), :mod:`.spot_slopes`
(displacements to slopes and their units), :mod:`.modal` and :mod:`.zonal` (reconstruction).

Conventions (project-wide): pixel centres sit at integer ``(row, col)``; image positions are
given as ``(col, row)``; physical coordinates are ``x = col`` and ``y = -row`` (x right, y up).
Lenslets of a grid are numbered row-major, ``k = i * cols + j`` for lenslet row ``i`` (top to
bottom) and lenslet column ``j`` (left to right), ``L = rows * cols``; those of a lattice in
the order of its ``sites``.

References
----------
.. [1] B. C. Platt and R. Shack, "History and principles of Shack-Hartmann wavefront
   sensing", J. Refract. Surg. 17, S573-S577 (2001).
.. [2] W. H. Southwell, "Wave-front estimation from wave-front slope measurements",
   J. Opt. Soc. Am. 70, 998-1006 (1980) (slope = displacement / focal length).
.. [3] S. Thomas, T. Fusco, A. Tokovinin, M. Nicolle, V. Michau and G. Rousset, "Comparison
   of centroid computation algorithms in a Shack-Hartmann sensor", Mon. Not. R. Astron. Soc.
   371, 323-336 (2006) (thresholded centre of gravity).
"""

from __future__ import annotations

from .centroids import Centroider, SpotMeasurement, camera_frame, centroid_spots
from .grid import LensletGrid
from .grid_detection import detect_grid
from .lattice import LatticeKind, LensletLattice
from .lattice_detection import detect_lattice
from .modal import ModalReconstructor
from .spot_slopes import SlopeResult, convert_slopes, slopes, slopes_in_waves_per_radius
from .zonal import SouthwellReconstructor, southwell_reconstruct

__all__ = [
    "Centroider",
    "LatticeKind",
    "LensletGrid",
    "LensletLattice",
    "ModalReconstructor",
    "SlopeResult",
    "SouthwellReconstructor",
    "SpotMeasurement",
    "camera_frame",
    "centroid_spots",
    "convert_slopes",
    "detect_grid",
    "detect_lattice",
    "slopes",
    "slopes_in_waves_per_radius",
    "southwell_reconstruct",
]
