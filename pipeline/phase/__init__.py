"""Phase: PSI and carrier demodulation, the fringe signal, and spatial and temporal unwrapping."""

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

__all__ = [
    "CarrierResult",
    "NO_MODULATION",
    "PhaseResult",
    "SpatialParams",
    "TemporalUnwrapper",
    "UnwrapResult",
    "advanced_iterative_psi",
    "carrier_phase",
    "contrast_box",
    "count_residues",
    "four_step",
    "fringe_energy",
    "hariharan_five_step",
    "least_squares_psi",
    "pca_psi",
    "phase_from_frames",
    "unwrap_spatial",
    "check_fringe_modulation",
    "wrap_phase",
]
