"""Where the simulated optic's starting surface comes from: Zernike terms, a measured map, roughness.

:func:`initial_heights_nm` adds the three sources of :class:`SurfaceSettings` on the camera grid.
Each covers the whole grid (aperture and margin: the polishing tool may touch the margin) and is
finite everywhere.

The disk
--------
Zernike terms and the measured map both refer to the aperture's circumscribing disk: centre
``(cx, cy)`` (column, row) and radius ``R`` pixels, the minimum enclosing circle of the aperture
mask's pixel centres (``Aperture.from_mask(mask).enclosing_circle()``), as the optic's own
``zernike_waves`` do (:mod:`wavestack.simulators.optic`).

* Zernike terms: ``sum_j c_j Z_j(u, v)`` with ``u = (col - cx) / R`` (right), ``v = (cy - row) / R``
  (up), unit-RMS over the disk (Noll 1976). Outside the disk (margin only: the aperture lies inside
  it) each point takes the value at the disk edge along its radius: continuous and bounded, where the
  polynomials themselves grow as ``rho^n`` and would put micrometres into the corners of the frame.
* A measured map: its unmeasured pixels are filled (holes inside the measured region's enclosing
  disk harmonically, the discrete Laplace equation with the measured pixels as boundary: smooth,
  exact for a plane, never beyond the surrounding values; beyond that disk by the nearest measured
  value, since the camera never sees that part), then it is resampled (bilinear,
  float64, after a Gaussian anti-alias blur when it shrinks) so that its measured region's enclosing disk
  lands on the aperture's disk, image rows down in both. Its piston over the aperture is removed
  and, if ``map_rms_nm`` is given, it is scaled to that RMS over the aperture.
* Roughness: :func:`~wavestack.simulators.roughness.gaussian_random_field` with the correlation
  length converted to pixels by ``pixel_mm``.

References
----------
.. [1] R. J. Noll, J. Opt. Soc. Am. 66, 207-211 (1976).
.. [2] W. H. Press et al., *Numerical Recipes*, 3rd ed., Cambridge (2007), sec. 20.5 (the discrete
   Dirichlet problem for Laplace's equation).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import scipy.ndimage
import scipy.sparse
import scipy.sparse.linalg
from numpy.typing import NDArray

from wavestack.pipeline import Aperture, InputError, load_map, mode_list, read_measured_map, zernike_basis
from wavestack.simulators.roughness import gaussian_random_field
from wavestack.simulators.surface_settings import SurfaceSettings

__all__ = ["initial_heights_nm", "measured_surface_nm", "zernike_surface_nm"]

logger = logging.getLogger(__name__)

_BLOCK = 1 << 15  # grid points per block when evaluating the Zernike basis


def initial_heights_nm(settings: SurfaceSettings, mask: NDArray[np.bool_]) -> NDArray[np.float64]:
    """The starting surface of ``settings`` on the grid of ``mask``: Zernike + map + roughness.

    Parameters
    ----------
    settings : SurfaceSettings
    mask : ndarray of bool, shape (H, W)
        The aperture the sources are scaled onto (module notes).

    Returns
    -------
    ndarray of float64, shape (H, W)
        Heights, nm, finite everywhere.

    Raises
    ------
    ValueError
        If the aperture is empty; :class:`~wavestack.pipeline.InputError` (a ValueError) naming
        the map file if it cannot be read or is flat while ``map_rms_nm`` asks for a scale.
    """
    mask = np.asarray(mask, dtype=bool)
    if not mask.any():
        raise ValueError("mask: expected an aperture with at least one pixel")
    heights = zernike_surface_nm(settings.zernike_nm, mask)
    if settings.map_file is not None:
        heights += measured_surface_nm(settings.map_file, mask, settings.map_rms_nm)
    if settings.roughness_rms_nm > 0:
        heights += gaussian_random_field(mask, rms_nm=settings.roughness_rms_nm, seed=settings.seed,
                                         correlation_px=settings.roughness_correlation_mm / settings.pixel_mm)
    return heights


def zernike_surface_nm(coefficients_nm: tuple[float, ...], mask: NDArray[np.bool_]) -> NDArray[np.float64]:
    """``sum_j c_j Z_j`` over the grid of ``mask`` (module notes), nm; zeros for no coefficient.

    Parameters
    ----------
    coefficients_nm : tuple of float
        Noll-ordered, piston first, nm, unit-RMS over the aperture's circumscribing disk.
    mask : ndarray of bool, shape (H, W)

    Returns
    -------
    ndarray of float64, shape (H, W)
    """
    height, width = mask.shape
    heights = np.zeros(height * width)
    if not any(coefficients_nm):
        return heights.reshape(height, width)
    cx, cy, radius = Aperture.from_mask(mask).enclosing_circle()
    rows, cols = np.divmod(np.arange(height * width), width)
    u, v = (cols - cx) / radius, (cy - rows) / radius
    rho = np.maximum(np.hypot(u, v), 1.0)  # radially constant outside the disk
    u, v = u / rho, v / rho
    modes = mode_list("noll", len(coefficients_nm))
    vector = np.asarray(coefficients_nm, dtype=np.float64)
    for start in range(0, heights.size, _BLOCK):
        block = slice(start, start + _BLOCK)
        heights[block] = zernike_basis(modes, u[block], v[block]) @ vector
    return heights.reshape(height, width)


def measured_surface_nm(path: str | Path, mask: NDArray[np.bool_], rms_nm: float | None) -> NDArray[np.float64]:
    """A measured map scaled onto the aperture's disk, piston-free, at ``rms_nm`` if given (module notes).

    Parameters
    ----------
    path : str or Path
        ``.dat``, ``.datx``, 4D ``.h5`` (read by :func:`~wavestack.pipeline.read_measured_map`), or a
        ``.npy`` array in nm with NaN where not measured.
    mask : ndarray of bool, shape (H, W)
        The aperture.
    rms_nm : float or None
        RMS over the aperture, nm; None keeps the file's heights.

    Returns
    -------
    ndarray of float64, shape (H, W)
        Heights, nm, finite everywhere, mean zero over the aperture.

    Raises
    ------
    InputError
        If the file cannot be read, or ``rms_nm`` is given for a map flat over the aperture.
    """
    path = Path(path)
    source = load_map(path) if path.suffix.lower() == ".npy" else np.array(read_measured_map(path).map_nm)
    valid = np.isfinite(source)
    filled = _filled(source, valid)
    heights = _onto_disk(filled, valid, mask)
    heights -= heights[mask].mean()
    if rms_nm is not None:
        spread = math.sqrt(float(np.mean(heights[mask] ** 2)))
        if spread <= 1e-12 * float(np.max(np.abs(source[valid]))):  # flat to rounding
            raise InputError(f"{path}: the map is flat over the aperture; cannot scale it to map_rms_nm = {rms_nm}")
        heights *= rms_nm / spread
    logger.info("measured map %s (%d x %d, %d measured pixels) scaled onto the aperture", path.name,
                *source.shape, int(np.count_nonzero(valid)))
    return heights


def _filled(source: NDArray[np.float64], valid: NDArray[np.bool_]) -> NDArray[np.float64]:
    """``source`` with its unmeasured pixels filled: harmonic inside the measured disk, nearest beyond."""
    nearest = scipy.ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
    filled = source[tuple(nearest)]
    cx, cy, radius = Aperture.from_mask(valid).enclosing_circle()
    rows, cols = np.indices(valid.shape)
    holes = ~valid & ((cols - cx) ** 2 + (rows - cy) ** 2 <= (radius + 1.0) ** 2)
    if holes.any():
        filled[holes] = _harmonic(filled, holes)
    return filled


def _harmonic(values: NDArray[np.float64], holes: NDArray[np.bool_]) -> NDArray[np.float64]:
    """The discrete Laplace equation solved on ``holes``, the other pixels of ``values`` its boundary.

    Each hole pixel is the mean of its in-frame 4-neighbours: exact for planes, smooth inside and
    within the boundary's range (maximum principle). Returns the values at ``holes``, row-major.
    """
    height, width = holes.shape
    number = -np.ones(holes.shape, dtype=np.int64)
    number[holes] = np.arange(np.count_nonzero(holes))
    rows, cols = np.nonzero(holes)
    degree = np.zeros(rows.size)
    rhs = np.zeros(rows.size)
    row_ids, col_ids = [], []
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        r, c = rows + dr, cols + dc
        inside = (r >= 0) & (r < height) & (c >= 0) & (c < width)
        degree += inside
        r, c, at = r[inside], c[inside], np.nonzero(inside)[0]
        unknown = holes[r, c]
        row_ids.append(at[unknown])
        col_ids.append(number[r[unknown], c[unknown]])
        np.add.at(rhs, at[~unknown], values[r[~unknown], c[~unknown]])
    links = np.concatenate(row_ids)
    matrix = scipy.sparse.csr_matrix((-np.ones(links.size), (links, np.concatenate(col_ids))), shape=(rows.size,) * 2)
    matrix = matrix + scipy.sparse.diags(degree)
    return scipy.sparse.linalg.spsolve(matrix.tocsc(), rhs)


def _onto_disk(filled: NDArray[np.float64], valid: NDArray[np.bool_], mask: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Resample ``filled`` so the enclosing disk of ``valid`` lands on that of ``mask`` (bilinear)."""
    src_cx, src_cy, src_radius = Aperture.from_mask(valid).enclosing_circle()
    cx, cy, radius = Aperture.from_mask(mask).enclosing_circle()
    scale = radius / max(src_radius, 0.5)  # destination pixels per source pixel
    if scale < 1.0:  # shrinking: blur to the destination's Nyquist limit first
        filled = scipy.ndimage.gaussian_filter(filled, 0.5 * math.sqrt(1.0 / scale**2 - 1.0), mode="nearest")
    # destination (row, col) -> source (row, col); pixel centres at integer points in both
    offset = (src_cy - cy / scale, src_cx - cx / scale)
    return scipy.ndimage.affine_transform(filled, (1.0 / scale, 1.0 / scale), offset=offset, output_shape=mask.shape,
                                          order=1, mode="nearest")
