"""Write a station recording: frame sets, apertures, result rows and configuration, crash-safe.

``wavestack run --record FILE.h5`` writes with :class:`RecordingWriter`. The layout is described in
:mod:`wavestack.recording.format`.

Crash safety
------------
The file is written with ``libver="latest"`` and switched to HDF5 SWMR mode (single writer,
multiple readers), whose ordered metadata flushes keep the file consistent on disk at any instant.
SWMR forbids creating datasets or attributes once it is on, and two sets of columns are only
known from the data: frame metadata keys (from the first set) and result columns (from the first
result). So SWMR starts as soon as both exist -- in the station, right after the first result --
or at creation when ``metadata_keys`` and ``result_template`` declare them up front. Until then
the file is NOT crash-safe: HDF5 marks it "open for write" and a killed writer leaves a file that
only ``h5clear -s`` reopens. Measured with h5py 3.16 / HDF5 2.0: a writer killed (SIGKILL) after
a flush but before SWMR left such a file; 20 writers killed at random times under SWMR (512x512
uint16, 4 frames a set, ~100 sets) all left files that opened and held every committed set,
aperture and result bit-exact.

The writer commits -- flushes all data, then writes ``committed_counts`` and flushes again --
when a set arrives after ``chunk_sets`` uncommitted ones, after a result once ``commit_interval_s``
has passed since the last commit, and on :meth:`RecordingWriter.flush` and ``close``. Committing
before the next set, or after a result, keeps each set's result (appended after the set) in the
same commit. The reader trusts only committed rows, so a row whose extent reached the disk before
its data can never be read back as zeros.

Loss window: a killed writer loses only what was appended since the last commit, which is never
more than ``chunk_sets`` sets (8 by default) with their results, and while results keep arriving
no more than ``commit_interval_s`` (1 s by default) of them, plus the set being appended.

Memory: the writer keeps no rows in Python; each row goes to HDF5 as it is appended. HDF5 holds
at most one chunk cache per open dataset (1 MiB each, about 30 datasets) and its metadata cache
(bounded by HDF5, a few MiB); a set larger than the chunk cache is written straight through.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from datetime import datetime, timezone
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np
from numpy.typing import DTypeLike, NDArray

from wavestack.drivers.frames import Frame
from wavestack.recording.format import (
    _FRAME_COLUMNS,
    FORMAT_NAME,
    FORMAT_VERSION,
    _append_rows,
    _column_name_ok,
    header_crc32,
    layout_crc32,
    set_crc32,
    _columns_of,
    _growable,
    ResultRow,
    _ResultColumns,
)

_log = logging.getLogger(__name__)


class RecordingWriter:
    """Append-only, crash-safe HDF5 recording of a running station (see the module docstring).

    Parameters
    ----------
    path
        File to create. An existing file is refused unless ``overwrite`` is true.
    config_toml
        The full configuration as TOML text (stored verbatim).
    conventions
        Named conventions (e.g. Zernike ordering, sign, units), str, int or float values.
    software_version
        wavestack version string.
    frame_shape
        (rows, cols) of every frame, pixels.
    frame_dtype
        Stored pixel dtype; frames must cast to it safely (uint8 into uint16 is fine).
    frames_per_set
        Frames in one set (1 for single-frame methods, N for an N-step phase-shifting set).
    chunk_sets
        Sets per commit: a crash loses at most this many sets (plus the one being appended) and
        their results. Call :meth:`flush` when the station idles to commit a partial chunk.
    commit_interval_s
        Commit after a result once this long has passed since the last commit, seconds.
    compress
        gzip level 1 with byte shuffle on pixels (off by default: 20 sets/s of 1024x1024 uint16
        is the target rate).
    overwrite
        Replace an existing file.
    metadata_keys
        Numeric frame-metadata columns; by default the numeric keys of the first set's frames.
        Numeric keys seen later are logged once and not stored (SWMR cannot add columns).
    result_template
        A record with the keys, types and shapes of every result; by default the first result.
        Declaring both ``metadata_keys`` and this makes the file crash-safe from creation.

    Raises
    ------
    FileExistsError
        ``path`` exists and ``overwrite`` is false.
    ValueError
        A bad argument (raised before the file is touched).

    Notes
    -----
    Not thread-safe: call it from one thread (the station's recording stage).
    """

    def __init__(self, path: str | Path, *, config_toml: str, conventions: Mapping[str, str | float | int],
                 software_version: str, frame_shape: tuple[int, int], frame_dtype: DTypeLike,
                 frames_per_set: int, chunk_sets: int = 8, compress: bool = False, overwrite: bool = False,
                 commit_interval_s: float = 1.0,
                 metadata_keys: Sequence[str] | None = None,
                 result_template: ResultRow | None = None) -> None:
        self.path = Path(path)
        shape = tuple(int(n) for n in frame_shape)
        if len(shape) != 2 or min(shape) < 1:
            raise ValueError(f"recording {self.path}: frame_shape must be (rows, cols) > 0, got {frame_shape}")
        dtype = np.dtype(frame_dtype)
        if dtype.kind not in "uif":
            raise ValueError(f"recording {self.path}: frame_dtype must be an integer or float dtype, got {dtype}")
        if not commit_interval_s > 0:
            raise ValueError(f"recording {self.path}: commit_interval_s must be > 0 s, got {commit_interval_s}")
        if frames_per_set < 1 or chunk_sets < 1:
            raise ValueError(f"recording {self.path}: frames_per_set and chunk_sets must be >= 1, "
                             f"got {frames_per_set} and {chunk_sets}")
        for key, value in conventions.items():
            if not isinstance(value, (str, int, float)) or not key or "/" in key:
                raise ValueError(f"recording {self.path}: convention {key!r} must be a str, int or float under a "
                                 f"name without '/', got {type(value).__name__}")
        declared_keys = None if metadata_keys is None else tuple(metadata_keys)
        for key in declared_keys or ():
            if not _column_name_ok(key):
                raise ValueError(f"recording {self.path}: metadata key {key!r} must be non-empty without '/'")
        template = None if result_template is None else _columns_of(result_template)
        if self.path.exists() and not overwrite:
            raise FileExistsError(f"{self.path}: a file already exists; refusing to overwrite a recording "
                                  "(pass overwrite=True to replace it)")
        self._frame_shape: tuple[int, int] = (shape[0], shape[1])
        self._dtype = dtype
        self._fps = int(frames_per_set)
        self._chunk_sets = int(chunk_sets)
        self._n_sets = self._n_apertures = self._n_results = 0
        self._since_commit = 0
        self._commit_interval_s = float(commit_interval_s)
        self._last_commit = time.monotonic()
        self._last_set_index: int | None = None
        self._last_aperture_from: int | None = None
        self._committed = (0, 0, 0)
        self._metadata_keys: tuple[str, ...] | None = None
        self._ignored_keys: set[str] = set()
        self._results: _ResultColumns | None = None
        self._warned_unsafe = False
        self._closed = False
        self._file = h5py.File(self.path, "w" if overwrite else "w-", libver="latest")
        try:
            self._create_layout(config_toml, conventions, software_version, compress)
            if declared_keys is not None:
                self._create_metadata_columns(declared_keys)
            if template is not None:
                self._results = _ResultColumns.create(self._file["results"], template)
            self._start_swmr_when_ready()
        except BaseException:
            self._file.close()
            self._closed = True
            self.path.unlink(missing_ok=True)  # no half-built recording left behind
            raise

    # -- layout ---------------------------------------------------------------------------------
    def _create_layout(self, config_toml: str, conventions: Mapping[str, str | float | int],
                       software_version: str, compress: bool) -> None:
        root = self._file
        root.attrs["format"] = FORMAT_NAME
        root.attrs["format_version"] = FORMAT_VERSION
        root.attrs["software_version"] = str(software_version)
        root.attrs["config_toml"] = str(config_toml)
        root.attrs["created_utc"] = datetime.now(timezone.utc).isoformat()
        group = root.create_group("conventions", track_order=True)
        for key, value in conventions.items():
            group.attrs[key] = value
        root.attrs["header_crc32"] = header_crc32(root.attrs, group.attrs)
        root.create_dataset("committed_counts", data=np.zeros(3, np.int64), chunks=(3,), fletcher32=True)
        integrity = root.create_group("integrity")
        _growable(integrity, "set_crc32", (), np.uint32)
        _growable(integrity, "result_crc32", (), np.uint32)
        sets = root.create_group("sets")
        rows, cols = self._frame_shape
        filters: dict[str, Any] = {"compression": "gzip", "compression_opts": 1, "shuffle": True} if compress else {}
        sets.create_dataset("pixels", shape=(0, self._fps, rows, cols), maxshape=(None, self._fps, rows, cols),
                            chunks=(1, self._fps, rows, cols), dtype=self._dtype, **filters)  # CRC-32 per set
        _growable(sets, "set_index", (), np.int64)
        for name in _FRAME_COLUMNS:
            _growable(sets, name, (self._fps,), np.int64)
        apertures = root.create_group("apertures")
        apertures.create_dataset("mask", shape=(0, rows, cols), maxshape=(None, rows, cols),
                                 chunks=(1, rows, cols), dtype=np.bool_, compression="gzip", compression_opts=1,
                                 fletcher32=True)
        _growable(apertures, "from_set", (), np.int64)
        root.create_group("results", track_order=True)

    def _create_metadata_columns(self, keys: tuple[str, ...]) -> None:
        group = self._file["sets"].create_group("metadata", track_order=True)
        for key in keys:
            _growable(group, key, (self._fps,), np.float64)
        self._metadata_keys = keys

    def _start_swmr_when_ready(self) -> None:
        if self._file.swmr_mode or self._metadata_keys is None or self._results is None:
            return
        self._write_layout_crc32()  # SWMR forbids new attributes: now or never
        self._file.swmr_mode = True  # flushes; from here on the file stays consistent on disk
        _log.info("recording %s: SWMR on, crash-safe from set %d", self.path, self._n_sets)

    def _write_layout_crc32(self) -> None:
        columns = () if self._results is None else self._results.columns
        self._file["integrity"].attrs["layout_crc32"] = layout_crc32(columns, self._metadata_keys or ())

    # -- public verbs ---------------------------------------------------------------------------
    @property
    def crash_safe(self) -> bool:
        """True once SWMR is on, i.e. a killed writer leaves a readable file."""
        return not self._closed and bool(self._file.swmr_mode)

    @property
    def committed_sets(self) -> int:
        """Sets durable on disk: a crash now keeps at least these, if :attr:`crash_safe`."""
        return self._committed[0]

    def append_set(self, set_index: int, frames: Sequence[Frame]) -> None:
        """Append one frame set.

        Parameters
        ----------
        set_index
            The station's set counter; strictly increasing (gaps allowed, e.g. a dropped set).
        frames
            ``frames_per_set`` frames, pixels of shape ``frame_shape``. Numeric metadata is stored
            as float64 per frame; other metadata (strings) is not stored.

        Raises
        ------
        ValueError
            Wrong frame count, shape or dtype, a non-increasing ``set_index``, or a closed recording.
        """
        self._check_open()
        if len(frames) != self._fps:
            raise ValueError(f"recording {self.path}: set {set_index} has {len(frames)} frames, "
                             f"expected frames_per_set={self._fps}")
        if self._last_set_index is not None and set_index <= self._last_set_index:
            raise ValueError(f"recording {self.path}: set_index {set_index} must exceed the previous "
                             f"{self._last_set_index}")
        pixels = np.empty((self._fps, *self._frame_shape), self._dtype)
        for j, frame in enumerate(frames):
            if frame.pixels.shape != self._frame_shape or not np.can_cast(frame.pixels.dtype, self._dtype, "safe"):
                raise ValueError(f"recording {self.path}: set {set_index} frame {j} is {frame.pixels.shape} "
                                 f"{frame.pixels.dtype}, expected {self._frame_shape} castable to {self._dtype}")
            pixels[j] = frame.pixels
        if self._metadata_keys is None:
            found = dict.fromkeys(k for f in frames for k in _numeric_metadata(f) if _column_name_ok(k))
            self._create_metadata_columns(tuple(found))
        assert self._metadata_keys is not None
        metadata = {key: np.full(self._fps, np.nan) for key in self._metadata_keys}
        for j, frame in enumerate(frames):
            for key, value in _numeric_metadata(frame).items():
                if key in metadata:
                    metadata[key][j] = value
                elif key not in self._ignored_keys and len(self._ignored_keys) < 64:  # bounded: a log, not a store
                    self._ignored_keys.add(key)
                    _log.warning("recording %s: frame metadata %r first seen at set %d is not a column "
                                 "(declare it in metadata_keys); not stored", self.path, key, set_index)
        if self._since_commit >= self._chunk_sets:
            self.flush()  # commit the previous chunk together with its results and apertures
        sets = self._file["sets"]
        frame_columns = [np.array([int(getattr(f, name)) for f in frames], np.int64) for name in _FRAME_COLUMNS]
        crc = set_crc32(pixels, set_index, frame_columns, list(metadata.values()))
        columns: list[tuple[h5py.Dataset, Any]] = [(sets["pixels"], pixels), (sets["set_index"], set_index)]
        columns += list(zip((sets[name] for name in _FRAME_COLUMNS), frame_columns))
        columns += [(sets["metadata"][key], values) for key, values in metadata.items()]
        columns += [(self._file["integrity/set_crc32"], crc)]
        _append_rows(columns, self._n_sets)
        self._n_sets += 1
        self._last_set_index = int(set_index)
        self._since_commit += 1
        self._start_swmr_when_ready()

    def append_aperture(self, set_index: int, mask: NDArray[np.bool_]) -> None:
        """Record the aperture used from ``set_index`` on (call it when the aperture changes).

        Parameters
        ----------
        set_index
            First set the mask applies to; not below the previous aperture's.
        mask
            bool, shape ``frame_shape``: True inside the aperture.

        Raises
        ------
        ValueError
            Wrong shape or dtype, a decreasing ``set_index``, or a closed recording.
        """
        self._check_open()
        mask = np.asarray(mask)
        if mask.dtype != np.bool_ or mask.shape != self._frame_shape:
            raise ValueError(f"recording {self.path}: aperture mask is {mask.shape} {mask.dtype}, "
                             f"expected bool {self._frame_shape}")
        if self._last_aperture_from is not None and set_index < self._last_aperture_from:
            raise ValueError(f"recording {self.path}: aperture set_index {set_index} is below the previous "
                             f"aperture's {self._last_aperture_from}")
        group = self._file["apertures"]
        _append_rows([(group["mask"], mask), (group["from_set"], set_index)], self._n_apertures)
        self._n_apertures += 1
        self._last_aperture_from = int(set_index)

    def append_result(self, record: ResultRow) -> None:
        """Append one result row.

        Parameters
        ----------
        record
            Column name -> bool, int, float, complex, str or numeric array (e.g. coefficients of
            shape (n_modes,)). The first record (or ``result_template``) fixes the columns: names,
            kinds and shapes.

        Raises
        ------
        ValueError
            A key missing or unknown, a shape or kind not matching its column (the message names
            the key), or a closed recording.
        """
        self._check_open()
        if self._results is None:
            self._results = _ResultColumns.create(self._file["results"], _columns_of(record))
            self._start_swmr_when_ready()
        crc = self._results.append(record, self._n_results)
        _append_rows([(self._file["integrity/result_crc32"], crc)], self._n_results)
        self._n_results += 1
        if time.monotonic() - self._last_commit >= self._commit_interval_s or self._since_commit >= self._chunk_sets:
            self.flush()

    def flush(self) -> None:
        """Make everything appended so far durable: flush data, then commit the row counts."""
        self._check_open()
        if not self._file.swmr_mode and not self._warned_unsafe:
            self._warned_unsafe = True
            _log.warning("recording %s: not crash-safe yet (SWMR starts once the first result fixes the "
                         "columns; pass result_template to start at creation)", self.path)
        self._file.flush()
        counts = (self._n_sets, self._n_apertures, self._n_results)
        self._file["committed_counts"][...] = counts
        self._file.flush()
        self._committed = counts
        self._since_commit = 0
        self._last_commit = time.monotonic()

    def close(self) -> None:
        """Flush and close; idempotent."""
        if self._closed:
            return
        try:
            if not self._file.swmr_mode:
                self._write_layout_crc32()
            self.flush()
        finally:
            self._closed = True
            self._file.close()
            _log.info("recording %s closed: %d sets, %d apertures, %d results", self.path,
                      self._n_sets, self._n_apertures, self._n_results)

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError(f"recording {self.path}: already closed")

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


def _numeric_metadata(frame: Frame) -> dict[str, float]:
    """The frame's numeric metadata as floats (bools as 0/1); strings and other values are left out."""
    return {key: float(value) for key, value in frame.metadata.items()
            if isinstance(value, (bool, int, float, np.bool_, np.integer, np.floating))}
