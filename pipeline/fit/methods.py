"""Fit methods: how each one turns an aperture's samples into basis columns.

* ``circle``: Zernike circle polynomials over the pupil circle.
* ``qr``: the same columns; the fitter reports their orthonormalised form (Gram-Schmidt over the
  samples, Swantner & Chow 1994) and converts back.
* ``annulus``: annular Zernike polynomials (Mahajan 1981) over the annulus ``eps <= rho <= 1`` of
  the pupil circle, on the pixels themselves (``eps`` given or measured,
  :mod:`wavestack.pipeline.fit.annulus`).
* ``csf-qcm``: Zernike (disk) or annular Zernike (annulus, obscuration ``r_in``) polynomials at
  the samples' images under the CSF-QCM map (:mod:`wavestack.pipeline.mapping.qcm`).
* ``conformal``: the same under a discrete conformal map (:mod:`wavestack.pipeline.mapping.conformal`),
  the baseline the paper compares against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._checks import int_at_least, one_of
from ..aperture import Aperture
from ..mapping import LAPLACIANS, MAX_TARGET_VERTICES, CanonicalMap, conformal_map, csf_qcm_map
from ..zernike import annular_zernike_basis, zernike_basis
from .map_domain import map_domain

METHODS = ("circle", "qr", "annulus", "conformal", "csf-qcm")
MAPPED_METHODS = ("conformal", "csf-qcm")


@dataclass(frozen=True)
class Samples:
    """The fitted pixels of an aperture.

    Attributes
    ----------
    flat_index : ndarray of intp, shape (N,)
        Row-major indices into a frame.
    rows, cols : ndarray of int, shape (N,)
        Pixel coordinates.
    x, y : ndarray, shape (N,)
        Physical coordinates in the pupil's unit disk (x right, y up).
    excluded : int
        Valid pixels left out because they lie outside a user-given pupil.
    """

    flat_index: NDArray[np.intp]
    rows: NDArray[np.intp]
    cols: NDArray[np.intp]
    x: NDArray[np.float64]
    y: NDArray[np.float64]
    excluded: int


@dataclass(frozen=True)
class MappingOptions:
    """Settings of the mapped methods.

    Attributes
    ----------
    laplacian : {"cotangent", "graph"}
        Weights of the CSF-QCM interior solve.
    mesh_vertices : int
        Approximate vertex count of the aperture mesh.
    angular_balance : bool
        Balance the CSF-QCM map's area over angle (:mod:`wavestack.pipeline.mapping.angular_balance`).
    """

    laplacian: str = "cotangent"
    mesh_vertices: int = 15000
    angular_balance: bool = True

    def __post_init__(self) -> None:
        one_of(self.laplacian, "laplacian", LAPLACIANS, voice="expected")
        int_at_least(self.mesh_vertices, "mesh_vertices", 100, voice="expected")
        if self.mesh_vertices > MAX_TARGET_VERTICES:
            raise ValueError(f"mesh_vertices: expected at most {MAX_TARGET_VERTICES} (a mesh finer than the pixels "
                             f"adds nothing), got {self.mesh_vertices}")


@dataclass(frozen=True)
class MethodColumns:
    """A method's unit-RMS basis on the samples, and the map behind it if any.

    Attributes
    ----------
    values : ndarray, shape (N, M)
    mapping : CanonicalMap or None
    """

    values: NDArray[np.float64]
    mapping: CanonicalMap | None = None


def canonical_map(aperture: Aperture, method: str, options: MappingOptions) -> CanonicalMap:
    """The map a mapped method uses.

    Raises
    ------
    UnsupportedAperture
        If the aperture is neither simply nor doubly connected.
    """
    if method == "csf-qcm":
        return csf_qcm_map(
            aperture,
            target_vertices=options.mesh_vertices,
            laplacian=options.laplacian,
            angular_balance=options.angular_balance,
        )
    return conformal_map(aperture, target_vertices=options.mesh_vertices)


def mapped_columns(
    mapping: CanonicalMap, samples: Samples, modes: list[tuple[int, int]]
) -> NDArray[np.float64]:
    """Zernike or annular Zernike columns at the samples' canonical images.

    Parameters
    ----------
    mapping : CanonicalMap
    samples : Samples
    modes : list of (n, m)

    Returns
    -------
    ndarray, shape (N, M)
    """
    image = mapping.map_points(samples.cols.astype(np.float64), -samples.rows.astype(np.float64))
    if mapping.r_in is None:
        return zernike_basis(modes, image[:, 0], image[:, 1], normalisation="rms")
    return annular_zernike_basis(modes, image[:, 0], image[:, 1], obscuration=mapping.r_in)


def method_columns(
    method: str,
    aperture: Aperture,
    samples: Samples,
    modes: list[tuple[int, int]],
    options: MappingOptions,
    obscuration: float | None = None,
    fit_mask: NDArray[np.bool_] | None = None,
) -> MethodColumns:
    """Basis columns of ``method`` on the samples.

    Parameters
    ----------
    method : {"circle", "qr", "annulus", "conformal", "csf-qcm"}
    aperture : Aperture
    samples : Samples
    modes : list of (n, m)
    options : MappingOptions
    obscuration : float, optional
        ``annulus`` only (required there): the obscuration ratio ``eps``.
    fit_mask : ndarray of bool, optional
        The pixels fitted when they are not the aperture's: a mapped method maps the aperture
        trimmed to them (:func:`~wavestack.pipeline.fit.map_domain.map_domain`).

    Returns
    -------
    MethodColumns

    Raises
    ------
    ValueError
        For an unknown method.
    UnsupportedAperture
        For a mapped method on an aperture that is neither simply nor doubly connected.
    """
    if method in ("circle", "qr"):
        return MethodColumns(zernike_basis(modes, samples.x, samples.y, normalisation="rms"))
    if method == "annulus":
        if obscuration is None:
            raise ValueError("obscuration: expected the obscuration ratio of the annulus method, got None")
        return MethodColumns(annular_zernike_basis(modes, samples.x, samples.y, obscuration=obscuration))
    if method in MAPPED_METHODS:
        mapping = canonical_map(map_domain(aperture, fit_mask), method, options)
        return MethodColumns(mapped_columns(mapping, samples, modes), mapping)
    raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
