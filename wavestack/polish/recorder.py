"""The campaign record: everything the loop measured and sent, in one HDF5 file, flushed as it goes.

Layout (format ``wavestack-polish-campaign``, version 1)::

    /                      attrs: format, format_version, created_utc, config_toml, pixel_mm,
                           wavelength_nm, reflection_factor; at the end final_phase, final_reason,
                           runs_done
    /aperture_mask         (H, W) bool: the campaign's aperture (the first trusted measurement's)
    /measurements/surface_nm   (n, H, W) float32, NaN outside the aperture: every trusted measurement
    /measurements/{rms_nm, pv_nm, noise_rms_nm, count, exposure_unix_s}   (n,)
    /runs/<field>          (r,) one column per :class:`~wavestack.polish.run_record.RunRecord` field
    /runs/measured_nm, dwell_s, predicted_residual_nm, measured_residual_nm   (r, H, W) float32
    /runs/job_file         (r,) the job file's bytes as written (vlen uint8)
    /events/{unix_s, text} (e,) every transition of the loop, with its reason

Every append and every update is followed by a flush, so a fault (a device, the machine, the
operator's Ctrl-C) loses nothing already measured or sent: a run is written when its job is handed
off (with NaN where its result is not known yet) and updated in place when it is. Maps are float32
(a surface of 100 nm keeps ~1e-5 nm), chunked one map per chunk, gzip level 1 with shuffle and
fletcher32 checksums. Not SWMR: the file grows new datasets and attributes as the campaign goes,
which SWMR forbids; a process killed between two flushes may leave the last write unreadable.
"""

from __future__ import annotations

import dataclasses
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from wavestack.polish.measurement import Measurement
from wavestack.polish.run_record import RunRecord

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "CampaignRecorder"]

FORMAT_NAME = "wavestack-polish-campaign"
FORMAT_VERSION = 1
_RUN_MAPS = ("measured_nm", "dwell_s", "predicted_residual_nm", "measured_residual_nm")
_MEASUREMENT_COLUMNS = {"rms_nm": np.float64, "pv_nm": np.float64, "noise_rms_nm": np.float64, "count": np.int64,
                        "exposure_unix_s": np.float64}


def _column_dtype(kind: Any) -> Any:
    return {"int": np.int64, "float": np.float64, "str": h5py.string_dtype()}[kind if isinstance(kind, str)
                                                                                else kind.__name__]


def _growable(group: h5py.Group, name: str, row_shape: tuple[int, ...], dtype: Any) -> None:
    extra: dict[str, Any] = {} if h5py.check_string_dtype(np.dtype(dtype)) else {"fletcher32": True}
    if row_shape:
        extra = {"compression": "gzip", "compression_opts": 1, "shuffle": True}
    group.create_dataset(name, shape=(0, *row_shape), maxshape=(None, *row_shape), chunks=(1 if row_shape else 64,
                         *row_shape), dtype=dtype, **extra)


def _append(dataset: h5py.Dataset, value: Any) -> int:
    index = dataset.shape[0]
    dataset.resize(index + 1, axis=0)
    dataset[index] = value
    return index


class CampaignRecorder:
    """Writes one campaign's record (module notes).

    Parameters
    ----------
    path : Path
        A new file (checked beforehand by the caller: ``check_recording_path``).
    shape : (int, int)
        The measurement grid.
    config_text : str
        The configuration the campaign ran with.
    attributes : dict
        More root attributes (numbers and strings): pixel_mm, wavelength_nm, reflection_factor.

    Example
    -------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     recorder = CampaignRecorder(Path(folder) / "c.h5", (4, 4), "", {})
    ...     recorder.event("measuring", "start")
    ...     recorder.close("target-met", "done", 0)
    ...     h5py.File(Path(folder) / "c.h5", "r")["events/text"].shape
    (1,)
    """

    def __init__(self, path: Path, shape: tuple[int, int], config_text: str, attributes: dict[str, Any]) -> None:
        self.path = Path(path)
        self._shape = (int(shape[0]), int(shape[1]))
        self._file = h5py.File(self.path, "w-", libver="latest", locking=False)  # readable while it runs
        self._closed = False
        root = self._file
        root.attrs["format"] = FORMAT_NAME
        root.attrs["format_version"] = FORMAT_VERSION
        root.attrs["created_utc"] = datetime.now(timezone.utc).isoformat()
        root.attrs["config_toml"] = config_text
        for key, value in attributes.items():
            root.attrs[key] = value
        measurements = root.create_group("measurements")
        _growable(measurements, "surface_nm", self._shape, np.float32)
        for name, dtype in _MEASUREMENT_COLUMNS.items():
            _growable(measurements, name, (), dtype)
        runs = root.create_group("runs", track_order=True)
        for spec in dataclasses.fields(RunRecord):
            _growable(runs, spec.name, (), _column_dtype(spec.type))
        for name in _RUN_MAPS:
            _growable(runs, name, self._shape, np.float32)
        runs.create_dataset("job_file", shape=(0,), maxshape=(None,), chunks=(16,),
                            dtype=h5py.vlen_dtype(np.uint8))
        events = root.create_group("events")
        _growable(events, "unix_s", (), np.float64)
        _growable(events, "text", (), h5py.string_dtype())
        self._file.flush()

    @property
    def runs(self) -> int:
        """Runs written so far."""
        return int(self._file["runs/run"].shape[0])

    def event(self, phase: str, text: str) -> None:
        """Append one transition (the phase entered and why)."""
        events = self._file["events"]
        _append(events["unix_s"], time.time())
        _append(events["text"], f"{phase}: {text}")
        self._file.flush()

    def measurement(self, measurement: Measurement) -> int:
        """Append a trusted measurement (the first also sets ``/aperture_mask``); returns its index."""
        self._check_shape(measurement.surface_nm, "measurement")
        if "aperture_mask" not in self._file:
            self._file.create_dataset("aperture_mask", data=measurement.mask, compression="gzip", fletcher32=True)
        group = self._file["measurements"]
        index = _append(group["surface_nm"], measurement.surface_nm.astype(np.float32))
        values = {"rms_nm": measurement.rms_nm, "pv_nm": measurement.pv_nm, "noise_rms_nm": measurement.noise_rms_nm,
                  "count": measurement.count, "exposure_unix_s": measurement.newest_exposure_ns * 1e-9}
        for name, value in values.items():
            _append(group[name], value)
        self._file.flush()
        return index

    def run_started(self, row: RunRecord, *, measured_nm: NDArray, dwell_s: NDArray, predicted_residual_nm: NDArray,
                    job_file: bytes) -> int:
        """Append a run as it is handed off (its result NaN until :meth:`run_updated`); returns its index."""
        maps = {"measured_nm": measured_nm, "dwell_s": dwell_s, "predicted_residual_nm": predicted_residual_nm,
                "measured_residual_nm": np.full(self._shape, np.nan)}
        runs = self._file["runs"]
        index = runs["run"].shape[0]
        for name, array in maps.items():
            self._check_shape(array, name)
            _append(runs[name], np.asarray(array, dtype=np.float32))
        _append(runs["job_file"], np.frombuffer(job_file, dtype=np.uint8))
        for spec in dataclasses.fields(RunRecord):
            _append(runs[spec.name], getattr(row, spec.name))
        self._file.flush()
        return index

    def run_updated(self, index: int, row: RunRecord, measured_residual_nm: NDArray | None = None) -> None:
        """Rewrite run ``index``'s row (and its measured residual, when measured)."""
        runs = self._file["runs"]
        if not 0 <= index < runs["run"].shape[0]:
            raise IndexError(f"run index {index} not recorded (0..{runs['run'].shape[0] - 1})")
        for spec in dataclasses.fields(RunRecord):
            runs[spec.name][index] = getattr(row, spec.name)
        if measured_residual_nm is not None:
            self._check_shape(measured_residual_nm, "measured residual")
            runs["measured_residual_nm"][index] = np.asarray(measured_residual_nm, dtype=np.float32)
        self._file.flush()

    def close(self, final_phase: str, final_reason: str, runs_done: int) -> None:
        """Write how the campaign ended and close the file; idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._file.attrs["final_phase"] = final_phase
            self._file.attrs["final_reason"] = final_reason
            self._file.attrs["runs_done"] = int(runs_done)
        finally:
            self._file.close()

    def _check_shape(self, array: NDArray, what: str) -> None:
        if np.shape(array) != self._shape:
            raise ValueError(f"{what}: expected a {self._shape} map, got {np.shape(array)}")
