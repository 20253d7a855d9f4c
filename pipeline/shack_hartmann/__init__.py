"""Shack-Hartmann spots to wavefront slopes: the lenslet lattice, centroiding, slope conversion.

A Shack-Hartmann sensor puts an array of lenslets (pitch ``p`` pixels on the camera, square or
hexagonal) in a pupil plane; each lenslet focuses its part of the beam to a spot on the
camera, and the spot moves by ``f * grad W`` when the wavefront ``W`` tilts over the lenslet
(``f`` the lenslet focal length). This package

1. describes the lenslets on the camera with one type, :class:`LensletLattice` (square and
   hexagonal are its two kinds, at any orientation: two basis vectors, an origin and the
   lenslets used; :meth:`LensletLattice.array` lays out a sensor's rows x cols array), found
   from a frame by the one detector, :func:`detect_lattice`, which refuses, with the reason,
   spots that lie on neither kind;
2. measures the spot centres by a thresholded centre of gravity, all lenslets in one
   vectorised pass, with everything that depends only on the lattice precomputed once
   (:class:`Centroider`); frames of any real dtype and memory layout enter through
   :func:`camera_frame`; :func:`lit_lenslets` is the one rule for which lenslets count;
3. turns spot displacements into wavefront slopes (:func:`slopes`) and re-expresses them in
   other units (:func:`convert_slopes`);
4. reconstructs the wavefront: modal (:class:`ModalReconstructor`, from the lenslet centres
   and slopes of any lattice) or zonal (Southwell, full square arrays only).

The signal path that strings these together for a sensor, frame by frame, is
:class:`wavestack.pipeline.instrument.ShackHartmannProcessor`.

The modules: :mod:`.lattice` and :mod:`.lattice_detection` (the lattice, and finding it),
:mod:`.centroids` (spot centres), :mod:`.lit` (which lenslets count), :mod:`.spot_slopes`
(displacements to slopes and their units), :mod:`.modal` and :mod:`.zonal` (reconstruction).

Conventions (project-wide): pixel centres sit at integer ``(row, col)``; image positions are
given as ``(col, row)``; physical coordinates are ``x = col`` and ``y = -row`` (x right, y up).
Lenslets are numbered in the order of the lattice's ``sites``; those of an array row-major,
``k = i * cols + j`` for lenslet row ``i`` (top to bottom) and column ``j`` (left to right).

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

from .centroids import Centroider, SpotMeasurement, camera_frame
from .lattice import LatticeKind, LensletLattice
from .lattice_detection import detect_lattice
from .lit import lit_lenslets
from .modal import ModalReconstructor
from .spot_slopes import SlopeResult, convert_slopes, slopes
from .zonal import SouthwellReconstructor, southwell_reconstruct

__all__ = [
    "Centroider",
    "LatticeKind",
    "LensletLattice",
    "ModalReconstructor",
    "SlopeResult",
    "SouthwellReconstructor",
    "SpotMeasurement",
    "camera_frame",
    "convert_slopes",
    "detect_lattice",
    "lit_lenslets",
    "slopes",
    "southwell_reconstruct",
]
