"""The lenslet array on the camera, square or hexagonal: two basis vectors, an origin and the lenslets used.

Real sensors carry square or hexagonal lenslet arrays, often turned against the pixel grid.
:class:`LensletLattice` describes both (the one lattice type of the package): lenslet ``k`` sits
at ``origin + n1_k a1 + n2_k a2`` for integer site indices ``(n1_k, n2_k)``. A square lattice
has ``|a1| = |a2|`` at 90 degrees, a hexagonal one ``|a1| = |a2|`` at 60 degrees. Positions are
``(col, row)`` pairs in pixels (conventions in :mod:`wavestack.pipeline.shack_hartmann`).

Arrays. :meth:`LensletLattice.array` lays out ``rows x cols`` lenslets as a sensor's datasheet
describes them: row ``i`` along ``a1``, rows stacked along ``a2``; on a hexagonal lattice every
odd row is shifted by half a pitch along ``a1`` (so the rows stay stacked, the array stays a
rectangle), and lenslets are numbered row-major, ``k = i * cols + j``.

Windows. Each lenslet is centroided in a square ``W x W`` pixel window centred on it (first
pixel the first pixel centre at or past ``centre - W / 2``), with ``W`` the side of the largest
axis-aligned square around a site that stays inside its Voronoi cell (the points nearer to it
than to any other site): the windows of neighbours never overlap. For an axis-aligned square
lattice that is ``floor(pitch)``, and the windows of a full rectangular array tile its bounding
box (:meth:`LensletLattice.rectangle`); for a hexagonal lattice with a1 along the columns it is
``pitch / (1/2 + sqrt(3)/2) = 0.732 pitch``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import finite_float, positive_int

__all__ = ["LatticeKind", "LensletLattice"]

_MIN_PITCH_PX = 4.0  # smallest lenslet pitch accepted, pixels
_EDGE_TOL = 1e-9  # pixels: a window edge this close to a pixel centre counts as on it

LatticeKind = Literal["square", "hexagonal"]

_ANGLES = {"square": 90.0, "hexagonal": 60.0}  # degrees between a1 and a2
_SHAPE_TOL = 0.01  # relative: |a1| and |a2| equal, and the angle right to 0.01 rad
_UNIT = {  # unit basis (e1, e2) of each kind, (d_col, d_row), a1 along the columns
    "square": np.array([[1.0, 0.0], [0.0, 1.0]]),
    "hexagonal": np.array([[1.0, 0.0], [0.5, 0.5 * math.sqrt(3.0)]]),
}


@dataclass(frozen=True, eq=False)
class LensletLattice:
    """Lenslets on a square or hexagonal lattice, at any orientation, as seen on the camera.

    Attributes
    ----------
    kind : {"square", "hexagonal"}
    basis_px : tuple of two (float, float)
        ``a1, a2``, each ``(d_col, d_row)`` in pixels: equal lengths (the pitch, ``>= 4``),
        90 degrees apart for a square lattice and 60 for a hexagonal one, to 1 %.
    origin_px : tuple of float
        ``(col, row)`` of the centre of site ``(0, 0)``, pixels.
    sites : ndarray of int, shape (L, 2)
        ``(n1, n2)`` of each lenslet used, distinct; lenslet ``k`` is centred at
        ``origin + n1 a1 + n2 a2``.

    Raises
    ------
    ValueError
        If the basis is not two finite vectors of one length ``>= 4`` px at the angle of
        ``kind``, the origin not two finite numbers, or the sites not distinct integer pairs.

    Examples
    --------
    >>> import math
    >>> hexagonal = LensletLattice("hexagonal", ((20.0, 0.0), (10.0, 10.0 * math.sqrt(3))),
    ...                            (50.0, 40.0), [(0, 0), (1, 0), (0, 1)])
    >>> hexagonal.centres().round(2).tolist()
    [[50.0, 40.0], [70.0, 40.0], [60.0, 57.32]]
    >>> hexagonal.pitch_px, hexagonal.window_width()
    (20.0, 14)
    """

    kind: LatticeKind
    basis_px: tuple[tuple[float, float], tuple[float, float]]
    origin_px: tuple[float, float]
    sites: NDArray[np.intp]

    def __post_init__(self) -> None:
        if self.kind not in _ANGLES:
            raise ValueError(f"kind must be 'square' or 'hexagonal', got {self.kind!r}")
        basis = _vectors(self.basis_px)
        lengths = np.hypot(basis[:, 0], basis[:, 1])
        if lengths.min() < _MIN_PITCH_PX:
            raise ValueError(f"basis_px: vectors must be at least {_MIN_PITCH_PX} px long, got {lengths.tolist()}")
        angle = math.degrees(math.acos(np.clip(basis[0] @ basis[1] / (lengths[0] * lengths[1]), -1.0, 1.0)))
        if abs(lengths[0] - lengths[1]) > _SHAPE_TOL * lengths.max() or abs(angle - _ANGLES[self.kind]) > math.degrees(
            _SHAPE_TOL
        ):
            raise ValueError(
                f"basis_px: a {self.kind} lattice needs two vectors of one length {_ANGLES[self.kind]:.0f} deg apart, "
                f"got lengths {lengths[0]:.3f} and {lengths[1]:.3f} px at {angle:.2f} deg"
            )
        try:
            origin = (finite_float(self.origin_px[0], "origin_px[0]"), finite_float(self.origin_px[1], "origin_px[1]"))
        except (TypeError, IndexError):
            raise ValueError(f"origin_px must be a pair (col, row), got {self.origin_px!r}") from None
        sites = _sites(self.sites)
        object.__setattr__(self, "basis_px", (tuple(map(float, basis[0])), tuple(map(float, basis[1]))))
        object.__setattr__(self, "origin_px", origin)
        object.__setattr__(self, "sites", sites)

    @classmethod
    def array(cls, kind: LatticeKind, pitch_px: float, shape: tuple[int, int], *, first_centre_px: tuple[float, float],
              orientation_deg: float = 0.0) -> LensletLattice:
        """A sensor's ``rows x cols`` lenslet array (module notes), numbered row-major.

        Parameters
        ----------
        kind : {"square", "hexagonal"}
        pitch_px : float
            Distance between neighbouring lenslets, pixels, ``>= 4``.
        shape : (int, int)
            ``(rows, cols)`` of lenslets, both ``>= 1``.
        first_centre_px : (float, float)
            ``(col, row)`` of the centre of lenslet ``(0, 0)``, pixels.
        orientation_deg : float
            Angle of the rows (``a1``) from the column axis towards the row axis, degrees.

        Returns
        -------
        LensletLattice
            Lenslet ``k = i * cols + j`` at site ``(j - i // 2, i)`` on a hexagonal lattice and
            ``(j, i)`` on a square one.

        Raises
        ------
        ValueError
            If an argument is out of range (as for the class).

        Examples
        --------
        >>> hexagonal = LensletLattice.array("hexagonal", 20.0, (2, 3), first_centre_px=(10.0, 10.0))
        >>> hexagonal.centres().round(2).tolist()
        [[10.0, 10.0], [30.0, 10.0], [50.0, 10.0], [20.0, 27.32], [40.0, 27.32], [60.0, 27.32]]
        """
        if kind not in _UNIT:
            raise ValueError(f"kind must be 'square' or 'hexagonal', got {kind!r}")
        pitch = finite_float(pitch_px, "pitch_px")
        if pitch < _MIN_PITCH_PX:
            raise ValueError(f"pitch_px must be >= {_MIN_PITCH_PX} pixels, got {pitch!r}")
        try:
            first = (finite_float(first_centre_px[0], "first_centre_px[0]"),
                     finite_float(first_centre_px[1], "first_centre_px[1]"))
            if len(first_centre_px) != 2:
                raise IndexError
        except (TypeError, IndexError):
            raise ValueError(f"first_centre_px must be a pair (col, row), got {first_centre_px!r}") from None
        try:
            rows, cols = shape
        except (TypeError, ValueError):
            raise ValueError(f"shape must be a pair (rows, cols), got {shape!r}") from None
        rows, cols = positive_int(rows, "shape[0]"), positive_int(cols, "shape[1]")
        angle = math.radians(finite_float(orientation_deg, "orientation_deg"))
        rotation = np.array([[math.cos(angle), math.sin(angle)], [-math.sin(angle), math.cos(angle)]])
        basis = pitch * _UNIT[kind] @ rotation
        i, j = np.divmod(np.arange(rows * cols), cols)
        sites = np.column_stack([j - i // 2 if kind == "hexagonal" else j, i])
        return cls(kind, (tuple(basis[0]), tuple(basis[1])), first, sites)

    @property
    def count(self) -> int:
        """Number of lenslets ``L``."""
        return int(self.sites.shape[0])

    @property
    def pitch_px(self) -> float:
        """Distance between neighbouring lenslets, pixels (the mean length of the basis vectors)."""
        basis = np.asarray(self.basis_px)
        return float(np.hypot(basis[:, 0], basis[:, 1]).mean())

    @property
    def orientation_deg(self) -> float:
        """Angle of ``a1`` from the column axis towards the row axis, degrees, in ``(-180, 180]``."""
        return math.degrees(math.atan2(self.basis_px[0][1], self.basis_px[0][0]))

    def centres(self) -> NDArray[np.float64]:
        """Lenslet centres ``(col, row)``, pixels, shape (L, 2)."""
        return np.asarray(self.origin_px) + self.sites @ np.asarray(self.basis_px)

    def centres_xy(self) -> NDArray[np.float64]:
        """Lenslet centres ``(x, y) = (col, -row)``, pixels, shape (L, 2) (the reconstructors' input)."""
        centres = self.centres()
        return np.column_stack([centres[:, 0], -centres[:, 1]])

    def cell_vertices(self) -> NDArray[np.float64]:
        """Corners of a lenslet's cell (its Voronoi cell) about its centre, ``(d_col, d_row)`` pixels.

        Returns
        -------
        ndarray, shape (4, 2) for a square lattice or (6, 2) for a hexagonal one
            A square of side ``pitch`` or a hexagon of circumradius ``pitch / sqrt(3)``, turned
            with the lattice, in order around the cell.
        """
        a1, a2 = np.asarray(self.basis_px)
        if self.kind == "square":
            return 0.5 * np.array([a1 + a2, a2 - a1, -a1 - a2, a1 - a2])
        # the hexagon's corners are the circumcentres of the triangles of neighbouring sites
        neighbours = np.array([a1, a2, a2 - a1, -a1, -a2, a1 - a2])
        return (neighbours + np.roll(neighbours, -1, axis=0)) / 3.0

    def rectangle(self) -> tuple[int, int] | None:
        """``(rows, cols)`` when the lenslets are a full, axis-aligned square array in row-major
        order (sites ``(j + c, i + r)``): their windows then form a block grid that is
        centroided without a per-lenslet gather. None otherwise."""
        (d_col, d_row), (e_col, e_row) = self.basis_px
        if self.kind != "square" or d_row != 0.0 or e_col != 0.0 or d_col != e_row:
            return None
        n1, n2 = self.sites[:, 0], self.sites[:, 1]
        cols = int(n1.max() - n1.min() + 1)
        rows = int(n2.max() - n2.min() + 1)
        if rows * cols != self.count:
            return None
        i, j = np.divmod(np.arange(self.count), cols)
        if not (np.array_equal(n1 - n1.min(), j) and np.array_equal(n2 - n2.min(), i)):
            return None
        return rows, cols

    def window_width(self) -> int:
        """Side ``W`` of the lenslet windows, pixels: the largest axis-aligned square around a
        site inside its Voronoi cell (module notes)."""
        a1, a2 = np.asarray(self.basis_px)
        neighbours = np.array([a1, a2, a1 - a2, a1 + a2])
        # the square of half-side h stays on the site's side of the bisector of neighbour n
        # while h (|n_col| + |n_row|) <= |n|^2 / 2
        half = np.min(np.sum(neighbours**2, axis=1) / (2.0 * np.abs(neighbours).sum(axis=1)))
        return int(math.floor(2.0 * half + _EDGE_TOL))

    def window_starts(self) -> tuple[NDArray[np.intp], NDArray[np.intp], int]:
        """Integer windows of every lenslet.

        Returns
        -------
        row_starts, col_starts : ndarray of int, shape (L,)
            First pixel row and column of each lenslet's window.
        width : int
            Window side ``W``, pixels.
        """
        width = self.window_width()
        centres = self.centres()
        starts = np.ceil(centres - 0.5 * width - _EDGE_TOL).astype(np.intp)
        return starts[:, 1], starts[:, 0], width

    def check_fits(self, frame_shape: tuple[int, int]) -> None:
        """Raise ValueError unless every lenslet window lies inside a frame of ``(rows, cols)``."""
        rows, cols, width = self.window_starts()
        outside = (rows < 0) | (cols < 0) | (rows + width > frame_shape[0]) | (cols + width > frame_shape[1])
        if outside.any():
            raise ValueError(
                f"{int(outside.sum())} of {self.count} lenslet windows of the {self.kind} lattice (pitch "
                f"{self.pitch_px:.3f} px) leave the frame of shape {tuple(frame_shape)}; expected all inside"
            )

    def with_sites(self, sites: ArrayLike) -> LensletLattice:
        """The same lattice with other lenslets used."""
        return LensletLattice(self.kind, self.basis_px, self.origin_px, np.asarray(sites))


def _vectors(value: object) -> NDArray[np.float64]:
    """Two finite 2-vectors as a (2, 2) array, or ValueError naming basis_px."""
    try:
        basis = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"basis_px must be two (d_col, d_row) vectors, got {value!r}") from None
    if basis.shape != (2, 2) or not np.all(np.isfinite(basis)):
        raise ValueError(f"basis_px must be two finite (d_col, d_row) vectors, got {value!r}")
    return basis


def _sites(value: object) -> NDArray[np.intp]:
    """Distinct integer site pairs as a read-only (L, 2) array, L >= 1."""
    sites = np.asarray(value)
    if sites.ndim != 2 or sites.shape[1] != 2 or sites.shape[0] == 0 or not np.issubdtype(sites.dtype, np.integer):
        raise ValueError(f"sites must be integer pairs of shape (L, 2) with L >= 1, got {sites.dtype} {sites.shape}")
    sites = sites.astype(np.intp)
    if np.unique(sites, axis=0).shape[0] != sites.shape[0]:
        raise ValueError("sites must be distinct; a lattice site holds one lenslet")
    sites.setflags(write=False)
    return sites
