"""Arrays and geometry: apertures, Zernike bases, fitters. Nothing here knows about ports.

The public face is ``from wavestack.pipeline import Aperture, build_fitter``; everything a user
of the fitters needs is re-exported here.
"""

from .annular import annular_radial, annular_zernike_basis, annular_zernike_gradient
from .aperture import Aperture, EmptyAperture, Topology, UnsupportedAperture
from .build import available_methods, build_fitter
from .conditioning import gram_condition, noise_gain
from .fitter import FitBasis, FitResult, Fitter, FitterDiagnostics, InvalidFrame, Pupil
from .io import InputError, load_map, load_mask
from .normal_equations import IllConditionedBasis
from .physical_terms import PhysicalTerms, remove_physical_terms
from .zernike import zernike_basis, zernike_gradient, zernike_radial
from .zernike_index import (
    ansi_to_nm,
    convert_coefficients,
    default_normalisation,
    fringe_to_nm,
    index_to_nm,
    mode_list,
    nm_to_ansi,
    nm_to_fringe,
    nm_to_index,
    nm_to_noll,
    noll_to_nm,
    normalisation_factor,
)

__all__ = [
    "Aperture",
    "EmptyAperture",
    "FitBasis",
    "FitResult",
    "Fitter",
    "FitterDiagnostics",
    "IllConditionedBasis",
    "InputError",
    "InvalidFrame",
    "PhysicalTerms",
    "Pupil",
    "Topology",
    "UnsupportedAperture",
    "annular_radial",
    "annular_zernike_basis",
    "annular_zernike_gradient",
    "ansi_to_nm",
    "available_methods",
    "build_fitter",
    "convert_coefficients",
    "default_normalisation",
    "fringe_to_nm",
    "gram_condition",
    "index_to_nm",
    "load_map",
    "load_mask",
    "mode_list",
    "nm_to_ansi",
    "nm_to_fringe",
    "nm_to_index",
    "nm_to_noll",
    "noise_gain",
    "noll_to_nm",
    "normalisation_factor",
    "remove_physical_terms",
    "zernike_basis",
    "zernike_gradient",
    "zernike_radial",
]
