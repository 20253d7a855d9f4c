"""Instrument processors: one per instrument kind, the signal path every command calls.

A processor turns one set of camera frames into one frozen outcome (``process(frames) ->
outcome``), keeping its state explicit and knowing nothing of devices, threads or outputs: the
live station, ``replay``, ``batch`` and ``analyze`` call the same one, so the same frames give
the same numbers whichever command reads them.

- :class:`ShackHartmannProcessor` (:mod:`.shack_hartmann`): spot frames to Zernike terms, on a
  square or hexagonal lenslet lattice (configured, or found in a reference frame), described by
  a :class:`ShackHartmannSetup` (:mod:`.sensor_setup`), its geometry built once per reference
  (:mod:`.lenslet_geometry`).
- :mod:`.records`: the small records an outcome carries into a result.
"""

from __future__ import annotations

from .lenslet_geometry import LensletGeometry, cells_inside, configured_lattice, lenslet_geometry
from .records import ApertureRecord, ReconstructorDiagnostics
from .sensor_setup import ShackHartmannSetup
from .shack_hartmann import (
    MODAL,
    LensletSlopes,
    ReconstructorCache,
    ShackHartmannProcessor,
    ShackHartmannState,
    SlopeOutcome,
)

__all__ = [
    "MODAL",
    "ApertureRecord",
    "LensletGeometry",
    "LensletSlopes",
    "ReconstructorCache",
    "ReconstructorDiagnostics",
    "ShackHartmannProcessor",
    "ShackHartmannSetup",
    "ShackHartmannState",
    "SlopeOutcome",
    "cells_inside",
    "configured_lattice",
    "lenslet_geometry",
]
