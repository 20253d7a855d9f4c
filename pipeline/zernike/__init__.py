"""Zernike polynomials: index conventions and normalisations, the circle and annular bases, the
conic null.
"""

from __future__ import annotations

from .annular import annular_radial, annular_zernike_basis, annular_zernike_gradient
from .circle import zernike_basis, zernike_gradient, zernike_radial
from .conic_null import (
    ConicTest,
    conic_sag_mm,
    implied_conic_constant,
    null_spherical_coefficients,
    null_wavefront_waves,
)
from .conversion import convert_coefficients
from .indices import (
    ansi_to_nm,
    first_index,
    fringe_to_nm,
    index_to_nm,
    mode_list,
    nm_to_ansi,
    nm_to_fringe,
    nm_to_index,
    nm_to_noll,
    noll_to_nm,
)
from .modes import Ordering, validate_mode
from .names import mode_name
from .normalisation import Normalisation, default_normalisation, normalisation_factor

__all__ = [
    "ConicTest",
    "Normalisation",
    "Ordering",
    "annular_radial",
    "annular_zernike_basis",
    "annular_zernike_gradient",
    "ansi_to_nm",
    "conic_sag_mm",
    "convert_coefficients",
    "default_normalisation",
    "first_index",
    "fringe_to_nm",
    "implied_conic_constant",
    "index_to_nm",
    "mode_list",
    "mode_name",
    "nm_to_ansi",
    "nm_to_fringe",
    "nm_to_index",
    "nm_to_noll",
    "noll_to_nm",
    "normalisation_factor",
    "null_spherical_coefficients",
    "null_wavefront_waves",
    "validate_mode",
    "zernike_basis",
    "zernike_gradient",
    "zernike_radial",
]
