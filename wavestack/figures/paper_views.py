"""What the seed paper's figures draw of each ``bench paper`` row (``bench paper --plots``): plain values.

The benchmark builds, for every aperture and method, a fitter (with its canonical map for the
mapped methods) and fits known truths; the figures need some of that beyond the table's numbers:
the mesh and its canonical image, the per-triangle area scale and |mu| (Figs. 3-5 of the seed
paper), the Gram matrix (Fig. 6) and one truth with its fit error (Fig. 7). :func:`paper_views`
takes them from the fitter the row was measured with; nothing is rebuilt.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline import Aperture, Fitter
from wavestack.pipeline.mapping import area_scales, beltrami_coefficients, triangle_areas


@dataclass(frozen=True, eq=False)
class MapView:
    """A canonical map as the figures draw it.

    Attributes
    ----------
    vertices : ndarray, shape (V, 2)
        Physical mesh vertices, pixels (x = column, y = -row).
    triangles : ndarray of int, shape (T, 3)
    canonical : ndarray, shape (V, 2)
        Each vertex's image in the unit disk or annulus.
    r_in : float or None
        Inner radius of the canonical annulus (None: the disk).
    area_scale : ndarray, shape (T,)
        Per-triangle area scale ``s`` normalised by the ratio of total areas (1: uniform), the
        quantity of the seed paper's Fig. 4 (section 3.1.2).
    beltrami : ndarray, shape (T,)
        Per-triangle ``|mu|`` (Eq. 3; Fig. 5).
    """

    vertices: NDArray[np.float64]
    triangles: NDArray[np.intp]
    canonical: NDArray[np.float64]
    r_in: float | None
    area_scale: NDArray[np.float64]
    beltrami: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class PaperViews:
    """One row's pictures: its maps (waves) and, for a mapped method, its canonical map.

    Attributes
    ----------
    aperture : str
        The paper aperture's name.
    label : str
        The method as the table names it (:attr:`PaperRow.label`).
    mask : ndarray of bool, shape (H, W)
    gram : ndarray, shape (M, M)
        ``G = H^T H / N`` of the method's unit-RMS basis on the aperture's pixels (Fig. 6).
    truth : ndarray, shape (H, W)
        The first seed's physical truth, waves, NaN outside (float32).
    error : ndarray, shape (H, W)
        Its reconstruction minus the truth, waves, NaN outside (float32).
    mapping : MapView or None
        None for the unmapped methods (circle, qr).
    """

    aperture: str
    label: str
    mask: NDArray[np.bool_]
    gram: NDArray[np.float64]
    truth: NDArray[np.float32]
    error: NDArray[np.float32]
    mapping: MapView | None


def basis_gram(fitter: Fitter) -> NDArray[np.float64]:
    """``G = H^T H / N`` of a fitter's own basis on its samples, shape (M, M).

    The columns are the fitter's surfaces of the unit coefficient vectors, so ``G`` is that of
    the basis in the fitter's output normalisation (unit RMS for the paper's Noll modes); its
    condition number is the row's kappa(G).
    """
    valid = None
    columns = []
    for unit in np.eye(fitter.n_modes):
        surface = fitter.surface(unit)
        valid = np.isfinite(surface) if valid is None else valid
        columns.append(surface[valid])
    basis = np.stack(columns, axis=1)
    return basis.T @ basis / basis.shape[0]


def _map_view(fitter: Fitter) -> MapView | None:
    mapping = fitter.mapping
    if mapping is None:
        return None
    mesh = mapping.mesh
    scale = area_scales(mesh.vertices, mapping.canonical, mesh.triangles)
    physical = triangle_areas(mesh.vertices, mesh.triangles)
    total_ratio = float(np.sum(np.abs(scale) * physical) / np.sum(physical))  # as map_quality normalises
    return MapView(vertices=np.asarray(mesh.vertices, dtype=np.float64), triangles=np.asarray(mesh.triangles),
                   canonical=np.asarray(mapping.canonical, dtype=np.float64), r_in=mapping.r_in,
                   area_scale=scale / total_ratio,
                   beltrami=np.abs(beltrami_coefficients(mesh.vertices, mapping.canonical, mesh.triangles)))


def paper_views(aperture_name: str, label: str, aperture: Aperture, fitter: Fitter,
                truth: NDArray[np.float64], reconstruction: NDArray[np.float64]) -> PaperViews:
    """The pictures of one row.

    Parameters
    ----------
    aperture_name, label : str
    aperture : Aperture
    fitter : Fitter
        The row's fitter.
    truth, reconstruction : ndarray, shape (N,)
        The first seed's truth and its fitted surface on the aperture's pixels (row-major order of
        ``np.nonzero(aperture.mask)``), waves.
    """
    rows, cols = np.nonzero(aperture.mask)
    truth_map = np.full(aperture.shape, np.nan, dtype=np.float32)
    error_map = np.full(aperture.shape, np.nan, dtype=np.float32)
    truth_map[rows, cols] = truth
    error_map[rows, cols] = reconstruction - truth
    return PaperViews(aperture=aperture_name, label=label, mask=aperture.mask.copy(), gram=basis_gram(fitter),
                      truth=truth_map, error=error_map, mapping=_map_view(fitter))
