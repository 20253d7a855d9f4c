"""Fitting: fit methods, building a fitter, the fitter and its results, the on-disk store, physical
terms.
"""

from __future__ import annotations

from .annulus import Obscuration, annulus_obscuration
from .auto import AUTO, AUTO_MAX_NOISE_GAIN
from .build import MAX_MODES, available_methods, build_fitter, check_basis_size
from .conditioning import gram_condition, noise_gain, normalised_gram
from .fitter import Fitter
from .methods import (
    MAPPED_METHODS,
    METHODS,
    MappingOptions,
    Samples,
    canonical_map as build_canonical_map,
    mapped_columns,
)
from .normal_equations import IllConditionedBasis
from .orthonormal import MAX_GRAM_CONDITION
from .physical_terms import PhysicalTerms, physical_term_basis, physical_term_names, remove_physical_terms
from .results import FitBasis, FitResult, FitterDiagnostics, InvalidFrame, Pupil
from .store import FitterStore, fitter_key, load_fitter, save_fitter

__all__ = [
    "AUTO",
    "AUTO_MAX_NOISE_GAIN",
    "MAX_MODES",
    "FitBasis",
    "FitResult",
    "Fitter",
    "FitterDiagnostics",
    "FitterStore",
    "IllConditionedBasis",
    "InvalidFrame",
    "MAPPED_METHODS",
    "MAX_GRAM_CONDITION",
    "METHODS",
    "MappingOptions",
    "Obscuration",
    "PhysicalTerms",
    "Pupil",
    "Samples",
    "annulus_obscuration",
    "available_methods",
    "check_basis_size",
    "build_canonical_map",
    "build_fitter",
    "fitter_key",
    "gram_condition",
    "load_fitter",
    "mapped_columns",
    "noise_gain",
    "normalised_gram",
    "physical_term_basis",
    "physical_term_names",
    "remove_physical_terms",
    "save_fitter",
]
