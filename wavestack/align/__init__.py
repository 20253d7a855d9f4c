"""Live alignment of an off-axis TMA: Zernike terms at field points -> sensitivity matrix -> hexapod.

One job per module: the terms of a map on the fixed aperture (:mod:`.terms`), the truncated-SVD
estimate from the design model's sensitivity matrix (:mod:`.estimator`; the model and its matrix
are the pipeline topic :mod:`wavestack.pipeline.telescope`), the correction within the hexapod's
step and limits (:mod:`.correction`), whether the camera resolves the fringes over the
misalignment range (:mod:`.fringes`), the loop's life as data (:mod:`.state`, on the loop
kernel's table), the measurement through the station service (:mod:`.station_source`), the
iterations as the history table the web view reads (:mod:`.history`), the record (:mod:`.recorder`,
on the kernel's checksummed record), the session (:mod:`.session`), and the loop that drives the
field stage, the measurement and the hexapod through them (:mod:`.loop`, on the kernel's runner).
"""

from __future__ import annotations

from wavestack.align.correction import PlannedMove, plan_move
from wavestack.align.estimator import Estimate, estimate_state
from wavestack.align.history import alignment_history
from wavestack.align.state import (
    TABLE,
    TERMINAL_PHASES,
    TRANSITIONS,
    AlignEvent,
    AlignPhase,
    AlignState,
    advance,
    judge_iteration,
)
from wavestack.align.terms import FIT_METHODS, TermFitter

__all__ = ["FIT_METHODS", "AlignEvent", "AlignPhase", "AlignState", "Estimate", "PlannedMove", "TABLE",
           "TERMINAL_PHASES", "TRANSITIONS", "TermFitter", "advance", "alignment_history", "estimate_state",
           "judge_iteration", "plan_move"]
