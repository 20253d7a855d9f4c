"""The campaign record: everything the polishing loop measured and sent, on the loop kernel's checksummed record.

Format ``wavestack-polish-campaign`` (the kernel's :mod:`~wavestack.loop.record`, version 2: a
CRC-32 per record, flushed per record, an existing file never overwritten). Header: the grid
(``shape``) and the command's attributes (pixel_mm, wavelength_nm, reflection_factor, solver,
target). Records, in the order they happened:

- ``event``: every transition of the loop with its reason;
- ``map`` (the kernel's :data:`~wavestack.loop.MAP_KIND`): every trusted measurement, the surface
  in nm (NaN outside the aperture; the first also holds the campaign's ``aperture_mask``), its RMS,
  PV, noise, count and exposure time, and its ``measurement`` index;
- ``run``: a run as it is handed off (its row, with NaN where the result is not known yet; the
  measured surface it was computed from, the dwell map, the predicted residual, the job file's
  bytes), and again when it is completed (the full row, and the measured residual when measured):
  the later record of the same ``run_index`` supersedes the earlier;
- ``end``: how the campaign ended.

A fault (a device, the machine, the operator's Ctrl-C) loses nothing already measured or sent.
:func:`read_polish_campaign` reads back every intact record, the damaged ones named.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wavestack.loop import MAP_KIND, CampaignWriter, read_campaign
from wavestack.polish.measurement import Measurement
from wavestack.polish.run_record import RunRecord

__all__ = ["FORMAT_NAME", "CampaignRecorder", "PolishCampaign", "RecordedMeasurement", "read_polish_campaign"]

FORMAT_NAME = "wavestack-polish-campaign"
_RUN_MAPS = ("measured_nm", "dwell_s", "predicted_residual_nm")


def _row_fields(row: RunRecord) -> dict[str, Any]:
    return dataclasses.asdict(row)


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
        More header values (numbers and words): pixel_mm, wavelength_nm, reflection_factor, ...

    Example
    -------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     recorder = CampaignRecorder(Path(folder) / "c.h5", (4, 4), "", {})
    ...     recorder.event("measuring", "start")
    ...     recorder.close("target-met", "done", 0)
    ...     read_polish_campaign(Path(folder) / "c.h5").ending["final_phase"]
    'target-met'
    """

    def __init__(self, path: Path, shape: tuple[int, int], config_text: str, attributes: dict[str, Any]) -> None:
        self._shape = (int(shape[0]), int(shape[1]))
        header = {"shape": list(self._shape), **{k: v for k, v in attributes.items() if k != "software_version"}}
        self._writer = CampaignWriter(Path(path), FORMAT_NAME, config_text, header,
                                      software_version=str(attributes.get("software_version", "")))
        self._measurements = 0
        self._runs = 0

    @property
    def path(self) -> Path:
        return self._writer.path

    @property
    def runs(self) -> int:
        """Runs handed off so far."""
        return self._runs

    def event(self, phase: str, text: str) -> None:
        """One transition (the phase entered and why)."""
        self._writer.event(phase, text)

    def measurement(self, measurement: Measurement) -> int:
        """A trusted measurement (the first also holds the aperture mask); returns its index."""
        self._check_shape(measurement.surface_nm, "measurement")
        fields = {"measurement": self._measurements, "rms_nm": measurement.rms_nm, "pv_nm": measurement.pv_nm,
                  "noise_rms_nm": measurement.noise_rms_nm, "count": measurement.count}
        self._writer.append_map(measurement.surface_nm, units="nm",
                                exposure_unix_s=measurement.newest_exposure_ns * 1e-9,
                                mask=measurement.mask if self._measurements == 0 else None, fields=fields)
        self._measurements += 1
        return self._measurements - 1

    def run_started(self, row: RunRecord, *, measured_nm: NDArray, dwell_s: NDArray, predicted_residual_nm: NDArray,
                    job_file: bytes) -> int:
        """A run as it is handed off (its result NaN until :meth:`run_updated`); returns its index."""
        maps = {"measured_nm": measured_nm, "dwell_s": dwell_s, "predicted_residual_nm": predicted_residual_nm}
        for name, values in maps.items():
            self._check_shape(values, name)
        index = self._runs
        self._writer.append("run", {"run_index": index, **_row_fields(row)}, {**maps, "job_file": job_file})
        self._runs += 1
        return index

    def run_updated(self, index: int, row: RunRecord, measured_residual_nm: NDArray | None = None) -> None:
        """Run ``index`` completed: its full row (and its measured residual, when measured).

        Raises
        ------
        IndexError
            No run ``index`` was handed off.
        """
        if not 0 <= index < self._runs:
            raise IndexError(f"run index {index} not recorded (0..{self._runs - 1})")
        arrays = {}
        if measured_residual_nm is not None:
            self._check_shape(measured_residual_nm, "measured residual")
            arrays["measured_residual_nm"] = measured_residual_nm
        self._writer.append("run", {"run_index": index, **_row_fields(row)}, arrays)

    def close(self, final_phase: str, final_reason: str, runs_done: int) -> None:
        """Write how the campaign ended and close the file; idempotent."""
        self._writer.close({"final_phase": final_phase, "final_reason": final_reason, "runs_done": int(runs_done)})

    def _check_shape(self, array: NDArray, what: str) -> None:
        if np.shape(array) != self._shape:
            raise ValueError(f"{what}: expected a {self._shape} map, got {np.shape(array)}")


@dataclass(frozen=True, eq=False)
class RecordedMeasurement:
    """One trusted measurement as recorded: the surface (H, W) in nm, float32, NaN outside; its figures."""

    surface_nm: NDArray[np.float32]
    rms_nm: float
    pv_nm: float
    noise_rms_nm: float
    count: int
    exposure_unix_s: float


@dataclass(frozen=True, eq=False)
class PolishCampaign:
    """A campaign record as read back: what is intact, and what is not.

    Attributes
    ----------
    header : dict
    config_text : str
    aperture_mask : ndarray (H, W) of bool or None
    measurements : tuple of RecordedMeasurement
        Every intact measurement, in order.
    runs : tuple of RunRecord
        The latest intact row of every run, in run order.
    run_maps : tuple of dict
        Per run (same order), its intact maps by name (``measured_nm``, ``dwell_s``,
        ``predicted_residual_nm``, ``measured_residual_nm``) and ``job_file`` (uint8).
    events : tuple of (phase, reason)
    ending : dict or None
        ``final_phase``, ``final_reason``, ``runs_done`` (None: the campaign did not end cleanly).
    damage : tuple of str
    """

    header: dict[str, Any]
    config_text: str
    aperture_mask: NDArray[np.bool_] | None
    measurements: tuple[RecordedMeasurement, ...]
    runs: tuple[RunRecord, ...]
    run_maps: tuple[dict[str, NDArray[Any]], ...]
    events: tuple[tuple[str, str], ...]
    ending: dict[str, Any] | None
    damage: tuple[str, ...]


def _number(value: Any) -> float:
    return math.nan if value is None else float(value)


def _measurement(arrays: dict[str, NDArray[Any]], fields: dict[str, Any]) -> RecordedMeasurement:
    return RecordedMeasurement(arrays["map"], _number(fields.get("rms_nm")), _number(fields.get("pv_nm")),
                               _number(fields.get("noise_rms_nm")), int(fields.get("count") or 0),
                               _number(fields.get("exposure_unix_s")))


def _row(fields: dict[str, Any]) -> RunRecord:
    values = {}
    for spec in dataclasses.fields(RunRecord):
        value = fields.get(spec.name)
        values[spec.name] = math.nan if value is None and spec.type in ("float", float) else value
    return RunRecord(**values)


def read_polish_campaign(path: Path) -> PolishCampaign:
    """Read a polishing campaign's record: every intact record, the damaged ones named.

    Raises
    ------
    InputError
        Not a polishing campaign record, or unreadable as a whole.
    """
    log = read_campaign(Path(path), FORMAT_NAME)
    maps = log.of_kind(MAP_KIND)
    mask = next((np.asarray(m.arrays["aperture_mask"], dtype=bool) for m in maps if "aperture_mask" in m.arrays), None)
    runs: dict[int, RunRecord] = {}
    run_maps: dict[int, dict[str, NDArray[Any]]] = {}
    for entry in log.of_kind("run"):
        index = int(entry.fields["run_index"])
        runs[index] = _row(dict(entry.fields))
        run_maps.setdefault(index, {}).update(entry.arrays)
    endings = log.of_kind("end")
    return PolishCampaign(dict(log.header), log.config_text, mask,
                          tuple(_measurement(dict(m.arrays), dict(m.fields)) for m in maps),
                          tuple(runs[k] for k in sorted(runs)), tuple(run_maps[k] for k in sorted(runs)),
                          tuple((str(e.fields["phase"]), str(e.fields["reason"])) for e in log.of_kind("event")),
                          dict(endings[-1].fields) if endings else None, log.damage)
