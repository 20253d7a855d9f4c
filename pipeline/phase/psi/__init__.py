"""Phase-shifting interferometry: the wrapped phase from N frames at N phase steps (fixed or estimated steps)."""

from __future__ import annotations

from .algorithms import four_step, hariharan_five_step, least_squares_psi, phase_from_frames
from .demodulation import PhaseResult
from .estimated_steps import advanced_iterative_psi, pca_psi

__all__ = [
    "PhaseResult",
    "advanced_iterative_psi",
    "four_step",
    "hariharan_five_step",
    "least_squares_psi",
    "pca_psi",
    "phase_from_frames",
]
