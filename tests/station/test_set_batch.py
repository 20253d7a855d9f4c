"""SetBatch's rule of what waits for a batched fit: psi sets wait (in order), carrier frames and
the one-by-one path never do (their next set may depend on this one's fit)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from wavestack.config import ProcessingSettings
from wavestack.pipeline import SyncFitterSource, processor_for
from wavestack.station import SetBatch


def _processor(settings: ProcessingSettings):  # type: ignore[no-untyped-def]
    interferometer = settings.interferometer()
    return processor_for(interferometer, SyncFitterSource(interferometer.fit))


def _dark(count: int) -> list[np.ndarray]:
    return [np.zeros((64, 64), np.uint16) for _ in range(count)]  # no fringes: invalid before any fit


@pytest.mark.parametrize(("method", "batched", "waits"), [("psi", True, True), ("psi", False, False),
                                                          ("carrier", True, False)])
def test_what_waits_for_a_batched_fit(method: str, batched: bool, waits: bool) -> None:
    settings = replace(ProcessingSettings(), method=method)
    processor = _processor(settings)
    batch: SetBatch[int] = SetBatch(processor, batched=batched)
    frames = _dark(settings.frames_per_set)
    early = [done for tag in range(3) for done in batch.add(frames, tag)]
    late = batch.flush()
    assert [tag for tag, _ in early + late] == [0, 1, 2]  # in order, each once
    assert (len(early), len(late)) == ((0, 3) if waits else (3, 0))
    stages = {outcome.reason.split(":")[0] for _, outcome in early + late if not outcome.valid}
    assert stages and stages <= {"phase", "aperture"} and all(not o.valid for _, o in early + late)


def test_a_group_size_below_one_is_refused() -> None:
    with pytest.raises(ValueError, match="group_sets"):
        SetBatch(_processor(ProcessingSettings()), group_sets=0)
