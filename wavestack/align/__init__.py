"""Live alignment of an off-axis TMA: Zernike terms at field points -> sensitivity matrix -> hexapod.

One job per module: the terms of a map on the fixed aperture (:mod:`.terms`), the sensitivity
matrix of the design model (:mod:`.sensitivity`), the truncated-SVD estimate (:mod:`.estimator`),
the correction within the hexapod's step and limits (:mod:`.correction`), whether the camera
resolves the fringes over the misalignment range (:mod:`.fringes`), the loop's life as data
(:mod:`.state`), and the loop that drives the field stage, the measurement and the hexapod
through them (:mod:`.loop`).
"""

from __future__ import annotations

from wavestack.align.correction import PlannedMove, plan_move
from wavestack.align.estimator import Estimate, estimate_state
from wavestack.pipeline.telescope import DOFS, Sensitivity, build_sensitivity, model_terms
from wavestack.align.state import (
    TERMINAL_PHASES,
    TRANSITIONS,
    AlignEvent,
    AlignPhase,
    AlignState,
    advance,
    judge_iteration,
)
from wavestack.align.terms import FIT_METHODS, TermFitter

__all__ = ["FIT_METHODS", "AlignEvent", "AlignPhase", "AlignState", "DOFS", "Estimate", "PlannedMove", "Sensitivity",
           "TERMINAL_PHASES", "TRANSITIONS", "TermFitter", "advance", "build_sensitivity", "estimate_state",
           "judge_iteration", "model_terms", "plan_move"]
