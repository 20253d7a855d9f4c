"""What a Shack-Hartmann processor needs to know of its sensor: the lenslet array, its optics, the rules.

:class:`ShackHartmannSetup` is the one description every caller gives the processor: the
station's ``[shack_hartmann]`` table, the same table applied to files
(``wavestack analyze --config``), or a lenslet description from the command line. Three ways
of placing the lenslets on the camera are told apart by two fields:

* ``offset_px`` given: the array as calibrated (``lattice``, ``pitch_px``, ``orientation_deg``,
  ``offset_px``, ``grid_shape``), the spots' reference the lenslet centres (``reference =
  "ideal"``): a live sensor. ``lattice = "auto"`` takes the kind from the reference frame
  (:mod:`~wavestack.pipeline.instrument.lenslet_geometry`).
* ``offset_px`` None and ``reference = "frame"``: the lattice found in a reference frame of a
  flat wavefront, the slopes the spot displacements against that frame's spots.
* ``offset_px`` None and ``reference = "ideal"``: the lattice found in the frame itself at the
  described ``pitch_px``, placed on its spots: the mean spot displacement (tilt) is then not
  measured.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from .._checks import finite_float, one_of
from ..shack_hartmann.lattice import _MIN_PITCH_PX
from ..zernike import mode_list

LatticeChoice = Literal["square", "hexagonal", "auto"]
ReferenceKind = Literal["ideal", "frame"]


@dataclass(frozen=True)
class ShackHartmannSetup:
    """A Shack-Hartmann sensor as the processor sees it (module notes for the three placements).

    Attributes
    ----------
    focal_length_um, pixel_um : float
        Lenslet focal length and camera pixel pitch, micrometres, ``> 0``.
    wavelength_nm : float
        The wavelength the coefficients are counted in, nm, ``> 0``.
    lattice : {"square", "hexagonal", "auto"}
        The array's kind; ``"auto"``: the kind the reference frame's spots lie on.
    pitch_px : float or None
        Lenslet pitch on the camera, pixels, ``>= 4``; None only with ``reference = "frame"``
        and no ``offset_px`` (then the reference frame's pitch).
    orientation_deg : float
        Angle of the array's rows from the column axis towards the row axis, degrees.
    offset_px : (float, float) or None
        Lenslet (0, 0) is centred at ``offset_px + pitch / 2`` along both axes (for an
        axis-aligned square array: its cell's top-left corner), pixels. None: the lattice is
        placed on the reference frame's spots.
    grid_shape : (int, int) or None
        ``(rows, cols)`` of the array; None: every lenslet whose cell lies inside the frame.
    reference : {"ideal", "frame"}
        The spot positions of a flat wavefront: the lenslet centres, or a reference frame's spots.
    pupil_px : (float, float, float) or None
        ``(col, row, radius)`` of the disk the Zernike terms live on, pixels; None: the disk
        the lenslets lit in the reference frame cover.
    modes : int
        Terms reconstructed, ``>= 3``, the first of ``ordering``, unit RMS over the pupil disk.
    ordering : {"noll", "ansi", "fringe"}
    centroid_threshold : float
        Thresholded centre of gravity: fraction of each window's peak, in ``[0, 1)``.
    min_intensity : float
        A thresholded spot below this is no spot, counts, ``>= 0``.
    lit_fraction : float
        A lenslet is lit at this fraction of a typical full spot, in ``[0, 1]``
        (:func:`~wavestack.pipeline.shack_hartmann.lit_lenslets`).
    min_lit_fraction : float
        Fewer lit pupil lenslets than this fraction: the frame gives no result, in ``[0, 1]``.
    max_condition : float
        A reconstructor worse conditioned is refused, ``>= 1``.
    reconstructor_cache : int
        Lit-lenslet sets kept with their reconstructor, ``>= 1``.

    Raises
    ------
    ValueError
        Naming the field and what was expected.
    """

    focal_length_um: float
    pixel_um: float
    wavelength_nm: float
    lattice: LatticeChoice = "auto"
    pitch_px: float | None = None
    orientation_deg: float = 0.0
    offset_px: tuple[float, float] | None = None
    grid_shape: tuple[int, int] | None = None
    reference: ReferenceKind = "ideal"
    pupil_px: tuple[float, float, float] | None = None
    modes: int = 36
    ordering: str = "noll"
    centroid_threshold: float = 0.1
    min_intensity: float = 0.0
    lit_fraction: float = 0.9
    min_lit_fraction: float = 0.5
    max_condition: float = 1e4
    reconstructor_cache: int = 8

    def __post_init__(self) -> None:
        for name in ("focal_length_um", "pixel_um", "wavelength_nm"):
            if not finite_float(getattr(self, name), name) > 0:
                raise ValueError(f"{name}: expected a number > 0, got {getattr(self, name)!r}")
        one_of(self.lattice, "lattice", ("square", "hexagonal", "auto"), voice="expected")
        one_of(self.reference, "reference", ("ideal", "frame"), voice="expected")
        if self.pitch_px is not None and not finite_float(self.pitch_px, "pitch_px") >= _MIN_PITCH_PX:
            raise ValueError(f"pitch_px: expected a lenslet pitch >= {_MIN_PITCH_PX} px, got {self.pitch_px!r}")
        if self.pitch_px is None and (self.offset_px is not None or self.reference == "ideal"):
            raise ValueError("pitch_px: expected the lenslet pitch; only a lattice found in a reference frame "
                             "(reference = 'frame', no offset_px) takes its pitch from the frame")
        finite_float(self.orientation_deg, "orientation_deg")
        mode_list(self.ordering, self.modes)  # the ordering and the mode count, checked
        if not 0.0 <= finite_float(self.centroid_threshold, "centroid_threshold") < 1.0:
            raise ValueError(f"centroid_threshold: expected a fraction in [0, 1), got {self.centroid_threshold!r}")
        for name in ("lit_fraction", "min_lit_fraction"):
            if not 0.0 <= finite_float(getattr(self, name), name) <= 1.0:
                raise ValueError(f"{name}: expected a fraction in [0, 1], got {getattr(self, name)!r}")
        if not finite_float(self.min_intensity, "min_intensity") >= 0.0:
            raise ValueError(f"min_intensity: expected counts >= 0, got {self.min_intensity!r}")
        if not finite_float(self.max_condition, "max_condition") >= 1.0:
            raise ValueError(f"max_condition: expected a condition number >= 1, got {self.max_condition!r}")
        if isinstance(self.reconstructor_cache, bool) or not isinstance(self.reconstructor_cache, int) \
                or self.reconstructor_cache < 1:
            raise ValueError(f"reconstructor_cache: expected an integer >= 1, got {self.reconstructor_cache!r}")
        if self.pupil_px is not None:
            cx, cy, radius = (finite_float(value, "pupil_px") for value in self.pupil_px)
            if not radius > 0:
                raise ValueError(f"pupil_px: expected a radius > 0 px, got {radius!r}")

    @property
    def gain_px(self) -> float:
        """Spot displacement per wavefront slope: ``f lambda / p**2``, pixels per (wave per pixel)."""
        return self.focal_length_um * (self.wavelength_nm * 1e-3) / self.pixel_um ** 2

    @property
    def placed_on_spots(self) -> bool:
        """True when the lattice is found in the reference frame rather than configured."""
        return self.offset_px is None

    @property
    def first_centre_px(self) -> tuple[float, float]:
        """``(col, row)`` of lenslet (0, 0)'s centre of the configured array, pixels."""
        if self.offset_px is None or self.pitch_px is None:
            raise ValueError("first_centre_px: the array is not configured (no offset_px)")
        half = 0.5 * self.pitch_px
        return self.offset_px[0] + half, self.offset_px[1] + half


def tilt_is_measured(setup: ShackHartmannSetup) -> bool:
    """False when the lattice is placed on the frame's own spots against the ideal centres (no tilt)."""
    return not (setup.placed_on_spots and setup.reference == "ideal")

