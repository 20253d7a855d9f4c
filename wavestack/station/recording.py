"""Station recording: frame sets, apertures, result rows and configuration in one HDF5 file.

``wavestack run --record FILE.h5`` writes with :class:`RecordingWriter`; ``wavestack replay FILE.h5``
reads back with :class:`RecordingReader`. Both are generic: a result row is any mapping of
numbers, bools, strings and numeric arrays, so this module does not know the station's result type.

The work is split by concept: :mod:`wavestack.station.recording_format` (names, HDF5 layout, the
result table), :mod:`wavestack.station.recording_writer` (appending and the crash-safe commit
protocol) and :mod:`wavestack.station.recording_reader` (reading committed rows back). This module
re-exports the public names, so ``from wavestack.station.recording import RecordingWriter`` works.
"""

from __future__ import annotations

from wavestack.station.recording_format import FORMAT_NAME, FORMAT_VERSION
from wavestack.station.recording_reader import RecordingReader
from wavestack.station.recording_writer import RecordingWriter

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "RecordingReader", "RecordingWriter"]
