"""Wavefront from Shack-Hartmann slopes: zonal (Southwell) least squares.

Slopes and units as for the modal reconstructor (:mod:`wavestack.pipeline.shack_hartmann.modal`).

Zonal. Southwell's geometry [1]_: the phase is estimated at the lenslet centres, and for
every pair of neighbouring valid lenslets the mean of their two slopes times the pitch equals
the phase difference. The sparse system is solved in the least-squares sense through its
normal equations (a graph Laplacian), factorised once with one phase pinned per connected
group of lenslets; piston is then set to zero mean over each group. (Fried's geometry, with
the phase at the lenslet corners, is not implemented: it has an unsensed waffle mode, and the
co-located Southwell estimate is what the modal results are compared with.) The neighbour
pairs are those of a full square array (rows and columns of lenslets, ``LensletLattice.rectangle``);
a hexagonal lattice goes through the modal reconstructor.

References
----------
.. [1] W. H. Southwell, "Wave-front estimation from wave-front slope measurements",
   J. Opt. Soc. Am. 70, 998-1006 (1980).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.csgraph
import scipy.sparse.linalg
from numpy.typing import ArrayLike, NDArray

from .._checks import positive_float

__all__ = ["SouthwellReconstructor", "southwell_reconstruct"]


logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class SouthwellReconstructor:
    """Southwell zonal least squares on a lenslet grid, factorised once.

    Attributes
    ----------
    valid : ndarray of bool, shape (rows, cols)
        Lenslets with usable slopes.
    pitch : float
        Lenslet pitch in the length unit of the slopes (pixels for slopes per pixel).
    estimated : ndarray of bool, shape (rows, cols)
        Lenslets whose phase is estimated: valid ones with at least one valid neighbour.
    groups : int
        Number of connected groups of estimated lenslets (each gets its own zero mean).
    """

    valid: NDArray[np.bool_]
    pitch: float
    estimated: NDArray[np.bool_]
    groups: int
    _pairs: tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]] = field(repr=False)
    _difference: scipy.sparse.csr_matrix = field(repr=False)  # (E, N): phase differences
    _unknowns: NDArray[np.intp] = field(repr=False)  # flat grid index of each unknown
    _free: NDArray[np.bool_] = field(repr=False)  # unknowns not pinned
    _labels: NDArray[np.intp] = field(repr=False)  # group of each unknown
    _solve: Callable[[NDArray[np.float64]], NDArray[np.float64]] = field(repr=False)

    @classmethod
    def build(cls, valid_grid: ArrayLike, pitch: float) -> SouthwellReconstructor:
        """Set up and factorise the normal equations for one validity pattern.

        Parameters
        ----------
        valid_grid : array_like of bool, shape (rows, cols)
            Lenslets with usable slopes.
        pitch : float
            Lenslet pitch, ``> 0``, in the length unit of the slopes.

        Returns
        -------
        SouthwellReconstructor

        Raises
        ------
        ValueError
            If ``valid_grid`` is not a 2-D boolean array, ``pitch`` is not positive and
            finite, or no two valid lenslets are neighbours.

        References
        ----------
        Southwell (1980), J. Opt. Soc. Am. 70, 998, Fig. 1(c) geometry.
        """
        valid = np.asarray(valid_grid)
        if valid.ndim != 2 or valid.dtype != np.bool_:
            raise ValueError(
                f"valid_grid must be a 2-D boolean array (rows, cols), got shape {valid.shape} "
                f"and dtype {valid.dtype}"
            )
        step = positive_float(pitch, "pitch")
        rows, cols = valid.shape
        index = np.arange(rows * cols).reshape(rows, cols)
        horizontal = valid[:, :-1] & valid[:, 1:]
        vertical = valid[:-1, :] & valid[1:, :]
        left, right = index[:, :-1][horizontal], index[:, 1:][horizontal]
        top, bottom = index[:-1, :][vertical], index[1:, :][vertical]
        ends_a = np.concatenate([left, top])  # phase difference = phase[b] - phase[a]
        ends_b = np.concatenate([right, bottom])
        if ends_a.size == 0:
            raise ValueError("valid_grid has no two neighbouring valid lenslets; nothing to reconstruct")
        unknowns = np.unique(np.concatenate([ends_a, ends_b]))
        position = np.full(rows * cols, -1)
        position[unknowns] = np.arange(unknowns.size)
        edges = ends_a.size
        difference = scipy.sparse.csr_matrix(
            (
                np.concatenate([-np.ones(edges), np.ones(edges)]),
                (np.tile(np.arange(edges), 2), np.concatenate([position[ends_a], position[ends_b]])),
            ),
            shape=(edges, unknowns.size),
        )
        normal = (difference.T @ difference).tocsc()
        groups, labels = scipy.sparse.csgraph.connected_components(normal, directed=False)
        free = np.ones(unknowns.size, dtype=bool)
        free[np.unique(labels, return_index=True)[1]] = False  # pin one phase per group
        solve = scipy.sparse.linalg.factorized(normal[free][:, free].tocsc())
        estimated = np.zeros(rows * cols, dtype=bool)
        estimated[unknowns] = True
        if groups > 1:
            logger.info("Southwell: %d separate groups of lenslets, each with its own piston", groups)
        return cls(
            valid=valid.copy(),
            pitch=step,
            estimated=estimated.reshape(rows, cols),
            groups=int(groups),
            _pairs=(left, right, top, bottom),
            _difference=difference,
            _unknowns=unknowns,
            _free=free,
            _labels=labels.astype(np.intp),
            _solve=solve,
        )

    def reconstruct(self, slopes_x: ArrayLike, slopes_y: ArrayLike) -> NDArray[np.float64]:
        """Phase at the lenslet centres from one set of slopes.

        For horizontal neighbours ``(i, j), (i, j+1)``:
        ``phi[i, j+1] - phi[i, j] = pitch * (sx[i, j] + sx[i, j+1]) / 2``; for vertical
        neighbours ``(i, j), (i+1, j)`` (row i+1 lies *below*, y is up):
        ``phi[i+1, j] - phi[i, j] = -pitch * (sy[i, j] + sy[i+1, j]) / 2``.

        Parameters
        ----------
        slopes_x, slopes_y : array_like, shape (rows, cols) or (rows * cols,)
            ``dW/dx`` and ``dW/dy`` (x right, y up) in wavefront units per length unit of
            the pitch; values at invalid lenslets are ignored.

        Returns
        -------
        ndarray, shape (rows, cols)
            Phase in the wavefront unit, zero mean over each connected group of lenslets;
            NaN where not estimated (invalid, or valid without a valid neighbour).

        Raises
        ------
        ValueError
            If the slopes have the wrong shape or are not finite at the valid lenslets.
        """
        rows, cols = self.valid.shape
        sx = _grid_values(slopes_x, (rows, cols), "slopes_x")
        sy = _grid_values(slopes_y, (rows, cols), "slopes_y")
        used = self.estimated.ravel()
        if not (np.all(np.isfinite(sx[used])) and np.all(np.isfinite(sy[used]))):
            raise ValueError("slopes_x and slopes_y must be finite at the valid lenslets")
        left, right, top, bottom = self._pairs
        steps = np.concatenate(
            [0.5 * self.pitch * (sx[left] + sx[right]), -0.5 * self.pitch * (sy[top] + sy[bottom])]
        )
        rhs = self._difference.T @ steps
        phase = np.zeros(self._unknowns.size)
        phase[self._free] = self._solve(rhs[self._free])
        means = np.bincount(self._labels, weights=phase) / np.bincount(self._labels)
        phase -= means[self._labels]
        out = np.full(rows * cols, np.nan)
        out[self._unknowns] = phase
        return out.reshape(rows, cols)


def southwell_reconstruct(
    slopes_x: ArrayLike, slopes_y: ArrayLike, valid_grid: ArrayLike, pitch: float
) -> NDArray[np.float64]:
    """Zonal least-squares phase at the lenslet centres (Southwell geometry).

    A one-shot convenience around :class:`SouthwellReconstructor` (build, then reconstruct);
    keep the reconstructor for a stream of frames with the same valid lenslets.

    Parameters
    ----------
    slopes_x, slopes_y : array_like, shape (rows, cols) or (rows * cols,)
        ``dW/dx`` and ``dW/dy`` (x right, y up), wavefront units per length unit of ``pitch``.
    valid_grid : array_like of bool, shape (rows, cols)
    pitch : float
        Lenslet pitch, ``> 0``.

    Returns
    -------
    ndarray, shape (rows, cols)
        Phase with zero mean (per connected group), NaN where not estimated.

    Raises
    ------
    ValueError
        As :meth:`SouthwellReconstructor.build` and :meth:`SouthwellReconstructor.reconstruct`.

    References
    ----------
    Southwell (1980), J. Opt. Soc. Am. 70, 998.
    """
    return SouthwellReconstructor.build(valid_grid, pitch).reconstruct(slopes_x, slopes_y)


def _grid_values(values: ArrayLike, shape: tuple[int, int], name: str) -> NDArray[np.float64]:
    """Slopes given as a (rows, cols) grid or flat, returned flat (rows * cols,)."""
    array = np.asarray(values, dtype=np.float64)
    if array.shape not in (shape, (shape[0] * shape[1],)):
        raise ValueError(f"{name} must have shape {shape} or ({shape[0] * shape[1]},), got {array.shape}")
    return array.reshape(-1)
