"""What the station writes into a recording: one fixed-shape row per result, sets, apertures.

A recording row has the same keys and shapes for every result, valid or not (an invalid result
has NaN coefficients and ``-1`` frame ids), so the file's columns are declared when it is created
and the file is crash-safe from its first flush.

Columns added since the first recordings (``residual_pv``, the frame and set counters
``frames_acquired`` .. ``sets_pending``, and in format version 3 ``pv``, ``pvr`` and the
data-quality counts ``quality_inside`` .. ``quality_clipped``, the surface figures
``surface_sag_nm`` .. ``surface_pvr_nm`` and the drawing's verdict ``spec_passed``,
``spec_limiting``) are only new columns: the reader
reads whatever columns a file has, so recordings made before them still read and replay (without
those columns).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from wavestack import __version__
from wavestack.config import StationConfig
from wavestack.pipeline import PixelQuality
from wavestack.recording.format import RowValue
from wavestack.recording.paths import check_recording_path
from wavestack.recording.writer import RecordingWriter
from wavestack.station import Counters, CycleRecord, StationResult
from wavestack.station.surface_stage import SurfaceRecord

#: The ISO form figures a row carries (column ``surface_<key>_nm``) and their names in :class:`FormFigures`.
SURFACE_FIGURES = {"sag": "SAG", "irr": "IRR", "rsi": "RSI", "rmst": "RMSt", "rmsi": "RMSi", "rmsa": "RMSa"}

#: Numeric frame metadata the station records (the piezo tags of phase-stepped frames).
FRAME_METADATA = ("pzt_commanded_v", "pzt_readback_v", "phase_step_rad")


def recording_row(result: StationResult, modes: int, frames_per_set: int) -> dict[str, RowValue]:
    """The fixed-shape row of one result."""
    coefficients = np.full(modes, np.nan)
    coefficients[: len(result.coefficients)] = result.coefficients
    frame_ids = np.full(frames_per_set, -1, dtype=np.int64)
    frame_ids[: len(result.frame_ids)] = result.frame_ids
    return {
        "index": result.index, "valid": result.valid, "reason": result.reason or "",
        "frame_ids": frame_ids, "exposure_time_ns": result.exposure_time_ns, "latency_ms": result.latency_ms,
        "coefficients": coefficients, "residual_rms": result.residual_rms, "residual_pv": result.residual_pv,
        "fitter": result.fitter or "", "fitter_fallback": result.fitter_fallback,
        "aperture_id": -1 if result.aperture is None or result.aperture.id is None else int(result.aperture.id),
        "aperture_changed": result.aperture_changed,
        "unwrap_path": result.unwrap_path or "",
        "truth_error_rms": np.nan if result.truth_error_rms is None else result.truth_error_rms,
        "sent_to_plc": result.output is not None and result.output.sent,
        **counter_columns(result.counters),
        "pv": result.pv, "pvr": result.pvr,
        **quality_columns(result.quality),
        **surface_columns(result.surface),
    }


def surface_columns(record: SurfaceRecord | None) -> dict[str, RowValue]:
    """The live surface figures as result columns: nm of surface (NaN without ``[surface]``), and the drawing's
    verdict (``spec_passed``: 1 pass, 0 fail, -1 no tolerance or no figures; ``spec_limiting``: the quantity
    nearest its limit, ``""`` without a verdict)."""
    columns: dict[str, RowValue] = {f"surface_{key}_nm": math.nan for key in SURFACE_FIGURES}
    columns.update(surface_pvr_nm=math.nan, spec_passed=-1, spec_limiting="")
    if record is None:
        return columns
    by_quantity = record.form.by_quantity()
    columns.update({f"surface_{key}_nm": float(by_quantity[name]) for key, name in SURFACE_FIGURES.items()})
    columns["surface_pvr_nm"] = float(record.pvr.pvr)
    if record.verdict is not None:
        columns.update(spec_passed=int(record.verdict.passed), spec_limiting=record.verdict.limiting.quantity)
    return columns


def quality_columns(quality: PixelQuality | None) -> dict[str, RowValue]:
    """The data-quality counts as result columns (``quality_inside`` .. ``quality_rim``; -1 without them)."""
    values = {} if quality is None else quality.to_json()
    return {f"quality_{key}": int(values.get(key, -1))
            for key in ("inside", "used", "low_modulation", "saturated", "untrusted_order", "clipped", "rim")}


def counter_columns(counters: Counters) -> dict[str, RowValue]:
    """The frame and set counters as result columns (``frames_acquired`` .. ``sets_pending``)."""
    f, s = counters.frames, counters.sets
    return {"frames_acquired": f.acquired, "frames_processed": f.processed, "frames_dropped": f.dropped,
            "frames_pending": f.pending, "sets_assembled": s.assembled, "sets_processed": s.processed,
            "sets_dropped": s.dropped, "sets_pending": s.pending}


def conventions(config: StationConfig) -> dict[str, str | float | int]:
    """The conventions a reader needs to interpret the coefficients."""
    p = config.processing
    shack_hartmann = config.station.kind == "shack-hartmann"
    return {"ordering": p.ordering, "normalisation": "rms", "coefficient_units": "waves of wavefront",
            "first_index": 1, "wavelength_nm": config.station.wavelength_nm,
            "method": "shack-hartmann" if shack_hartmann else p.method,
            "fit_method": "modal" if shack_hartmann else p.fit_method, "remove": p.remove, "modes": p.modes,
            "calibration_sha256": "" if config.calibration is None else config.calibration.digest}


def open_recording(path: str, config: StationConfig, frame_shape: tuple[int, int], frame_dtype: Any,
                   *, overwrite: bool = False) -> RecordingWriter:
    """A recording for this station, its columns declared up front.

    Raises
    ------
    InputError
        ``path`` cannot take a new recording (see :func:`check_recording_path`).
    """
    check_recording_path(path, overwrite=overwrite)
    fps = config.processing.frames_per_set
    # the columns' types and shapes, from an empty row (every row has the same ones)
    template = recording_row(StationResult.invalid(0, "", Counters.zero(fps), ordering=config.processing.ordering),
                             config.processing.modes, fps)
    return RecordingWriter(path, config_toml=config.text, conventions=conventions(config),
                           software_version=__version__, frame_shape=frame_shape, frame_dtype=frame_dtype,
                           frames_per_set=fps, overwrite=overwrite, metadata_keys=FRAME_METADATA,
                           result_template=template)


class StationRecorder:
    """Appends each result, its set and any new aperture to a :class:`RecordingWriter`."""

    def __init__(self, writer: RecordingWriter, config: StationConfig) -> None:
        self._writer = writer
        self._modes = config.processing.modes
        self._fps = config.processing.frames_per_set

    def __call__(self, record: CycleRecord) -> None:
        result = record.result
        if record.frames:
            self._writer.append_set(result.index, record.frames)
            if record.new_aperture_mask is not None:
                self._writer.append_aperture(result.index, record.new_aperture_mask)
        self._writer.append_result(recording_row(result, self._modes, self._fps))

    def close(self) -> None:
        self._writer.close()
