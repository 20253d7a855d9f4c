"""Phase: PSI and carrier demodulation, spatial and temporal unwrapping, and the measured wavefront."""

from __future__ import annotations

from .carrier import CarrierResult, carrier_phase
from .measurement import (
    MeasuredWavefront,
    check_fringe_modulation,
    local_fringe_contrast,
    wavefront_from_carrier,
    wavefront_from_phase_shifts,
)
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
    "MeasuredWavefront",
    "PhaseResult",
    "SpatialParams",
    "TemporalUnwrapper",
    "UnwrapResult",
    "advanced_iterative_psi",
    "carrier_phase",
    "count_residues",
    "four_step",
    "hariharan_five_step",
    "least_squares_psi",
    "local_fringe_contrast",
    "pca_psi",
    "phase_from_frames",
    "unwrap_spatial",
    "wavefront_from_carrier",
    "wavefront_from_phase_shifts",
    "check_fringe_modulation",
    "wrap_phase",
]
