"""Arrays and geometry: apertures, Zernike bases, fitters. Nothing here knows about ports.

The public face is ``from wavestack.pipeline import Aperture, build_fitter``; everything a user
of the fitters needs is re-exported here.
"""

from .annular import annular_radial, annular_zernike_basis, annular_zernike_gradient
from .aperture import Aperture, EmptyAperture, Topology, UnsupportedAperture
from .aperture_detect import ApertureTracker, DetectionSettings, detect_aperture
from .carrier import carrier_phase
from .conic_null import ConicTest, implied_conic_constant
from .build import available_methods, build_fitter
from .conditioning import gram_condition, noise_gain
from .fitter import FitBasis, FitResult, Fitter, FitterDiagnostics, InvalidFrame, Pupil
from .fitter_store import FitterStore, load_fitter, save_fitter
from .images import read_frame, read_frame_set
from .io import InputError, load_map, load_mask
from .measurement import MeasuredWavefront, wavefront_from_carrier, wavefront_from_phase_shifts
from .normal_equations import IllConditionedBasis
from .physical_terms import PhysicalTerms, remove_physical_terms
from .psi import phase_from_frames
from .unwrap import TemporalUnwrapper, unwrap_spatial
from .zernike import zernike_basis, zernike_gradient, zernike_radial
from .zygo import read_datx, read_metropro_dat
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

from .zernike_index import mode_name
from .methods import MappingOptions, Samples, mapped_columns
from .methods import canonical_map as build_canonical_map
from .shack_hartmann import Centroider, LensletGrid, SpotMeasurement, convert_slopes, slopes
from .slope_reconstruction import ModalReconstructor
from .aperture_detect import compare_apertures
from .aperture_watch import ApertureWatch
from .measurement import local_fringe_contrast
from .unwrap import SpatialParams
from .conic_null import null_wavefront_waves
from .psi import four_step, hariharan_five_step
from .qcm import csf_qcm_map

__all__ = [
    "mode_name",
    "MappingOptions",
    "Samples",
    "mapped_columns",
    "build_canonical_map",
    "Centroider",
    "LensletGrid",
    "SpotMeasurement",
    "convert_slopes",
    "slopes",
    "ModalReconstructor",
    "compare_apertures",
    "ApertureWatch",
    "local_fringe_contrast",
    "SpatialParams",
    "null_wavefront_waves",
    "four_step",
    "hariharan_five_step",
    "csf_qcm_map",
    "Aperture",
    "ApertureTracker",
    "ConicTest",
    "DetectionSettings",
    "EmptyAperture",
    "FitBasis",
    "FitResult",
    "Fitter",
    "FitterDiagnostics",
    "FitterStore",
    "IllConditionedBasis",
    "InputError",
    "InvalidFrame",
    "MeasuredWavefront",
    "PhysicalTerms",
    "Pupil",
    "TemporalUnwrapper",
    "Topology",
    "UnsupportedAperture",
    "annular_radial",
    "annular_zernike_basis",
    "annular_zernike_gradient",
    "ansi_to_nm",
    "available_methods",
    "build_fitter",
    "carrier_phase",
    "convert_coefficients",
    "default_normalisation",
    "detect_aperture",
    "fringe_to_nm",
    "gram_condition",
    "implied_conic_constant",
    "index_to_nm",
    "load_fitter",
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
    "phase_from_frames",
    "read_datx",
    "read_frame",
    "read_frame_set",
    "read_metropro_dat",
    "remove_physical_terms",
    "save_fitter",
    "unwrap_spatial",
    "wavefront_from_carrier",
    "wavefront_from_phase_shifts",
    "zernike_basis",
    "zernike_gradient",
    "zernike_radial",
]
