"""Shack-Hartmann spots to wavefront slopes: lenslet grid, centroiding, slope conversion.

A Shack-Hartmann sensor puts a square array of lenslets (pitch ``p`` pixels on the camera) in
a pupil plane; lenslet ``(i, j)`` focuses its part of the beam to a spot on the camera, and
the spot moves by ``f * grad W`` when the wavefront ``W`` tilts over the lenslet (``f`` the
lenslet focal length). This package

1. describes the lenslet grid on the camera (:class:`LensletGrid`) and finds it from a
   reference frame (:func:`detect_grid`);
2. measures the spot centres by a thresholded centre of gravity, all lenslets in one
   vectorised pass, with everything that depends only on the grid precomputed once
   (:class:`Centroider`, :func:`centroid_spots`);
3. turns spot displacements into wavefront slopes (:func:`slopes`) and re-expresses them in
   other units (:func:`convert_slopes`, :func:`slopes_in_waves_per_radius`).

The modules: :mod:`.grid` (the lenslet grid), :mod:`.grid_detection` (finding it),
:mod:`.centroids` (spot centres), :mod:`.lit` (which lenslets count as lit), :mod:`.spot_slopes`
(displacements to slopes and their units), :mod:`.modal` and :mod:`.zonal` (reconstruction).

Conventions (project-wide): pixel centres sit at integer ``(row, col)``; image positions are
given as ``(col, row)``; physical coordinates are ``x = col`` and ``y = -row`` (x right, y up).
Lenslets are numbered row-major, ``k = i * cols + j`` for lenslet row ``i`` (top to bottom)
and lenslet column ``j`` (left to right); ``L = rows * cols``.

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
from .modal import ModalReconstructor
from .spot_slopes import SlopeResult, convert_slopes, slopes, slopes_in_waves_per_radius
from .zonal import SouthwellReconstructor, southwell_reconstruct

__all__ = [
    "Centroider",
    "LensletGrid",
    "ModalReconstructor",
    "SlopeResult",
    "SouthwellReconstructor",
    "SpotMeasurement",
    "camera_frame",
    "centroid_spots",
    "convert_slopes",
    "detect_grid",
    "slopes",
    "slopes_in_waves_per_radius",
    "southwell_reconstruct",
]
