"""Station recording: frame sets, apertures, result rows and configuration in one HDF5 file.

``wavestack run --record FILE.h5`` writes with :class:`RecordingWriter`; ``wavestack replay FILE.h5``
reads back with :class:`RecordingReader`. Both are generic: a result row is any mapping of
numbers, bools, strings and numeric arrays, so they do not know the station's result type.

The work is split by concept: :mod:`wavestack.recording.format` (names, HDF5 layout, the
result table, the checksums), :mod:`wavestack.recording.writer` (appending and the crash-safe
commit protocol), :mod:`wavestack.pipeline.formats.hdf5_open` (opening without SWMR read mode, which
hung on damaged files), :mod:`wavestack.recording.reader` (reading committed rows back, reporting
damage), :mod:`wavestack.recording.paths` (the ``--record`` path checked before devices open),
:mod:`wavestack.recording.station_rows` (what the station writes: one fixed-shape row per
result) and :mod:`wavestack.recording.replay` (the pipeline run again on a recording). This
package re-exports the public names, so ``from wavestack.recording import RecordingWriter`` works.
"""

from __future__ import annotations

from wavestack.recording.format import FORMAT_NAME, FORMAT_VERSION, ResultRow, RowValue
from wavestack.recording.paths import check_recording_path
from wavestack.recording.reader import Damage, RecordingDamaged, RecordingReader
from wavestack.recording.replay import ReplayedResult, SkippedSet, recorded_config, replay
from wavestack.recording.station_rows import (
    FRAME_METADATA,
    StationRecorder,
    conventions,
    open_recording,
    recording_row,
)
from wavestack.recording.writer import RecordingWriter

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "FRAME_METADATA", "Damage", "RecordingDamaged", "RecordingReader",
           "RecordingWriter", "ReplayedResult", "ResultRow", "RowValue", "SkippedSet", "StationRecorder",
           "check_recording_path", "conventions", "open_recording", "recorded_config", "recording_row", "replay"]
