"""Phase: PSI and carrier demodulation, spatial and temporal unwrapping, the measured wavefront, and
units.
"""

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
    "MeasuredWavefront",
    "PhaseResult",
    "SpatialParams",
    "TemporalUnwrapper",
    "UnwrapResult",
    "WavefrontUnits",
    "advanced_iterative_psi",
    "carrier_phase",
    "count_residues",
    "four_step",
    "hariharan_five_step",
    "least_squares_psi",
    "local_fringe_contrast",
    "nm_to_phase",
    "nm_to_waves",
    "pca_psi",
    "phase_from_frames",
    "phase_to_nm",
    "phase_to_waves",
    "surface_to_wavefront",
    "unwrap_spatial",
    "wavefront_from_carrier",
    "wavefront_from_phase_shifts",
    "check_fringe_modulation",
    "wavefront_to_surface",
    "waves_to_nm",
    "waves_to_phase",
    "wrap_phase",
]
