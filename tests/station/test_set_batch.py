"""SetBatch's rule of what waits for a batched fit: psi sets wait (in order), carrier frames and
the one-by-one path never do (their next set may depend on this one's fit)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from wavestack.config import ProcessingSettings
from wavestack.station import SetBatch, SetProcessor


def _dark(count: int) -> list[np.ndarray]:
    return [np.zeros((64, 64), np.uint16) for _ in range(count)]  # no fringes: invalid before any fit


@pytest.mark.parametrize(("method", "batched", "waits"), [("psi", True, True), ("psi", False, False),
                                                          ("carrier", True, False)])
def test_what_waits_for_a_batched_fit(method: str, batched: bool, waits: bool) -> None:
    settings = replace(ProcessingSettings(), method=method)
    processor = SetProcessor(settings, background_builds=False)
    try:
        batch: SetBatch[int] = SetBatch(processor, batched=batched)
        frames = _dark(settings.frames_per_set)
        early = [done for tag in range(3) for done in batch.add(frames, tag)]
        late = batch.flush()
    finally:
        processor.close()
    assert [tag for tag, _ in early + late] == [0, 1, 2]  # in order, each once
    assert (len(early), len(late)) == ((0, 3) if waits else (3, 0))
    stages = {outcome.reason.split(":")[0] for _, outcome in early + late if not outcome.valid}
    assert stages and stages <= {"phase", "aperture"} and all(not o.valid for _, o in early + late)


def test_a_group_size_below_one_is_refused() -> None:
    processor = SetProcessor(ProcessingSettings(), background_builds=False)
    try:
        with pytest.raises(ValueError, match="group_sets"):
            SetBatch(processor, group_sets=0)
    finally:
        processor.close()
