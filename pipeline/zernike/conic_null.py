"""The numerical null of a conic mirror tested at its centre of curvature.

A concave conic of vertex radius R and conic constant K, tested with a point source and the
interferometer focus at its paraxial centre of curvature C (no null lens), returns a wavefront
that is not spherical unless K = 0. Its sag is

    z(h) = h^2 / (R (1 + sqrt(1 - (1 + K) h^2 / R^2)))

and the double-pass path from C to the surface point P(h) and back differs from the sphere's
2R by

    W(h) = 2 (|C - P(h)| - R),   |C - P|^2 = h^2 + (R - z(h))^2.

This is exact along the incident ray; by Fermat's principle the returning ray's path differs
from it only to second order in the (micrometre) departure from the sphere, far below the
measurement. It holds all orders of spherical aberration, not only the fourth-order term
``W ~ -K h^4 / (4 R^3)`` of the usual approximation (the conic departs from the sphere by
``K h^4 / (8 R^3)`` towards C, shortening the double pass by twice that).

wavestack's sign convention (:mod:`wavestack.pipeline.phase.psi`) makes a positive wavefront a
positive phase; which physical path that is depends on which arm the phase shifter lengthens.
:func:`implied_conic_constant` therefore reports the K whose null matches the measured
spherical term under that convention; a reversed phase-step direction would give -K.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
from numpy.typing import NDArray

from .circle import zernike_basis
from .indices import nm_to_noll

_RADIAL_ORDERS = tuple(range(0, 21, 2))  # rotationally symmetric Zernike terms up to n = 20


@dataclass(frozen=True)
class ConicTest:
    """A conic mirror tested at its centre of curvature.

    Attributes
    ----------
    radius_of_curvature_mm : float
        Vertex radius R (positive for a concave mirror).
    diameter_mm : float
        Diameter of the tested aperture.
    wavelength_nm : float
        Test wavelength.
    """

    radius_of_curvature_mm: float
    diameter_mm: float
    wavelength_nm: float

    def __post_init__(self) -> None:
        for name in ("radius_of_curvature_mm", "diameter_mm", "wavelength_nm"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name}: expected a finite positive number, got {value!r}")
        if self.diameter_mm >= 2 * self.radius_of_curvature_mm:
            raise ValueError(
                f"diameter_mm: expected less than twice the radius of curvature "
                f"({2 * self.radius_of_curvature_mm} mm), got {self.diameter_mm}"
            )


def conic_sag_mm(h_mm: NDArray[np.float64], radius_mm: float, conic: float) -> NDArray[np.float64]:
    """Sag of a conic of vertex radius R and conic constant K at height h (mm).

    Raises
    ------
    ValueError
        If the conic is not defined at some height (``(1 + K) h^2 > R^2``).
    """
    argument = 1.0 - (1.0 + conic) * np.square(h_mm) / radius_mm**2
    if np.any(argument < 0):
        raise ValueError(f"conic: K = {conic} is not defined over this aperture (R = {radius_mm} mm)")
    return np.square(h_mm) / (radius_mm * (1.0 + np.sqrt(argument)))


def null_wavefront_waves(rho: NDArray[np.float64], test: ConicTest, conic: float) -> NDArray[np.float64]:
    """Wavefront (waves) the conic returns at its centre of curvature, at normalised radius rho.

    Parameters
    ----------
    rho : ndarray
        Radius over the tested aperture's radius, 0..1.
    test : ConicTest
    conic : float
        Conic constant K (0 sphere, -1 paraboloid).

    Returns
    -------
    ndarray
        ``2 (|C - P| - R)`` in waves, piston and defocus included (fit them out as needed).
    """
    h = np.asarray(rho, dtype=np.float64) * test.diameter_mm / 2.0
    radius = test.radius_of_curvature_mm
    distance = np.hypot(h, radius - conic_sag_mm(h, radius, conic))
    return 2.0 * (distance - radius) * 1e6 / test.wavelength_nm


def null_spherical_coefficients(test: ConicTest, conic: float) -> dict[int, float]:
    """Noll unit-RMS coefficients (waves) of the null wavefront's rotationally symmetric terms.

    The wavefront is projected on Z(n, 0), n = 0, 2, ..., 20, over the unit disk with a
    Gauss-Legendre quadrature in rho^2 that is exact for these polynomials.

    Returns
    -------
    dict
        Noll index -> coefficient; e.g. ``[11]`` is primary spherical, ``[22]`` secondary.
    """
    nodes, weights = np.polynomial.legendre.leggauss(64)
    t = (nodes + 1.0) / 2.0  # t = rho^2 in [0, 1]; d(area)/pi = dt
    rho = np.sqrt(t)
    modes = [(n, 0) for n in _RADIAL_ORDERS]
    basis = zernike_basis(modes, rho, np.zeros_like(rho))
    values = null_wavefront_waves(rho, test, conic)
    coefficients = basis.T @ (values * weights / 2.0)  # mean over the disk of Z * W
    return {nm_to_noll(n, 0): float(c) for (n, _), c in zip(modes, coefficients)}


def implied_conic_constant(spherical_waves: float, test: ConicTest, bounds: tuple[float, float] = (-10.0, 10.0)) -> float:
    """The conic constant whose null has the measured primary spherical term (Noll Z11).

    Parameters
    ----------
    spherical_waves : float
        Measured Noll Z11 coefficient, unit-RMS normalisation, in waves.
    test : ConicTest
    bounds : (float, float)
        Search interval for K.

    Returns
    -------
    float

    Raises
    ------
    ValueError
        If no K in ``bounds`` matches (the spherical term is out of range).
    """
    def mismatch(conic: float) -> float:
        return null_spherical_coefficients(test, conic)[11] - spherical_waves

    low, high = bounds
    if mismatch(low) * mismatch(high) > 0:
        raise ValueError(
            f"spherical_waves: {spherical_waves} waves is outside the range of conics K in {bounds}"
        )
    return float(scipy.optimize.brentq(mismatch, low, high, xtol=1e-10))
