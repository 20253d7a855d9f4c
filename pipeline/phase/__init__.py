"""Phase: PSI and carrier demodulation, the fringe signal, spatial and temporal unwrapping, and units."""

from __future__ import annotations

from .carrier import CarrierResult, carrier_phase
from .fringe_signal import NO_MODULATION, check_fringe_modulation, contrast_box, fringe_energy
from .psi import (
    PhaseResult,
    advanced_iterative_psi,
    four_step,
    hariharan_five_step,
    least_squares_psi,
    pca_psi,
    phase_from_frames,
)
from .spatial_unwrap import SpatialParams, count_residues, unwrap_spatial, wrap_phase
from .temporal_unwrap import TemporalUnwrapper, UnwrapResult
from .units import (
    WavefrontUnits,
    nm_to_phase,
    nm_to_waves,
    phase_to_nm,
    phase_to_waves,
    surface_to_wavefront,
    wavefront_to_surface,
    waves_to_nm,
    waves_to_phase,
)

__all__ = [
    "CarrierResult",
    "NO_MODULATION",
    "PhaseResult",
    "SpatialParams",
    "TemporalUnwrapper",
    "UnwrapResult",
    "WavefrontUnits",
    "advanced_iterative_psi",
    "carrier_phase",
    "contrast_box",
    "count_residues",
    "four_step",
    "fringe_energy",
    "hariharan_five_step",
    "least_squares_psi",
    "nm_to_phase",
    "nm_to_waves",
    "pca_psi",
    "phase_from_frames",
    "phase_to_nm",
    "phase_to_waves",
    "surface_to_wavefront",
    "unwrap_spatial",
    "check_fringe_modulation",
    "wavefront_to_surface",
    "waves_to_nm",
    "waves_to_phase",
    "wrap_phase",
]
