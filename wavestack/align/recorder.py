"""The alignment run's HDF5 record: the configuration, one group per iteration, how it ended.

Layout (``h5py``)::

    /                       attrs: format "wavestack-align", version 1, config_text, dofs,
                            field_points_deg, final_phase, reason, iterations_done, halted
    /iterations/NNN         attrs: iteration; datasets rms_waves (F,), and when the iteration
                            corrected: estimate (5,), move (5,), read_back (6,) with attrs axes

The file is flushed after each iteration, so a run that ends by a crash keeps what it measured;
:meth:`AlignRecorder.close` is idempotent (the first close's ending is the one kept).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from wavestack.align.loop import AlignSummary, IterationRecord
from wavestack.pipeline.telescope import DOFS

__all__ = ["AlignRecorder"]


class AlignRecorder:
    """Record an alignment run (module notes).

    Parameters
    ----------
    path : Path
        A new file (checked by the caller).
    config_text : str
    field_points_deg : sequence of (float, float)

    Examples
    --------
    >>> import tempfile, os
    >>> folder = tempfile.mkdtemp()
    >>> recorder = AlignRecorder(Path(folder) / "a.h5", "", [(0.0, 0.0)])
    >>> recorder.iteration(IterationRecord(0, (0.05,)))
    >>> recorder.close("target-met", "done", 0, None)
    >>> with h5py.File(Path(folder) / "a.h5") as f:
    ...     f.attrs["final_phase"], float(f["iterations/000/rms_waves"][0])
    ('target-met', 0.05)
    """

    def __init__(self, path: Path, config_text: str, field_points_deg) -> None:  # noqa: ANN001
        self._file: h5py.File | None = h5py.File(path, "w")
        attrs = self._file.attrs
        attrs["format"], attrs["version"] = "wavestack-align", 1
        attrs["config_text"] = config_text
        attrs["dofs"] = " ".join(DOFS)
        attrs["field_points_deg"] = np.asarray(field_points_deg, dtype=np.float64)
        attrs["final_phase"], attrs["reason"] = "running", ""
        self._file.create_group("iterations")

    def iteration(self, record: IterationRecord) -> None:
        """Append one iteration and flush."""
        if self._file is None:
            raise ValueError("the alignment record is closed")
        group = self._file["iterations"].create_group(f"{record.iteration:03d}")
        group.attrs["iteration"] = record.iteration
        group["rms_waves"] = np.asarray(record.rms_waves, dtype=np.float64)
        if record.estimate is not None:
            group["estimate"] = np.asarray(record.estimate, dtype=np.float64)
        for name, values in (("move", record.move), ("read_back", record.read_back)):
            if values is not None:
                group[name] = np.array(list(values.values()), dtype=np.float64)
                group[name].attrs["axes"] = " ".join(values)
        self._file.flush()

    def close(self, phase: str, reason: str, iterations_done: int, halted: bool | None) -> None:
        """Write how the run ended and close (idempotent)."""
        if self._file is None:
            return
        attrs = self._file.attrs
        attrs["final_phase"], attrs["reason"], attrs["iterations_done"] = phase, reason, iterations_done
        attrs["halted"] = "unknown" if halted is None else str(halted).lower()
        self._file.close()
        self._file = None

    def finish(self, summary: AlignSummary) -> None:
        """:meth:`close` with a summary's ending."""
        self.close(summary.state.phase.value, summary.state.reason or "", summary.state.iterations_done,
                   summary.halted)
