"""The on-disk format of a station recording: names, layout and the result table.

Shared by :mod:`wavestack.recording.writer` and :mod:`wavestack.recording.reader`
(both re-exported by :mod:`wavestack.recording`).

Layout (``format_version`` 3)::

    /                       attrs: format, format_version, software_version, config_toml, created_utc,
                            header_crc32
    /conventions            attrs: one per convention (str, int or float)
    /committed_counts       int64 (3,): sets, apertures, results durable on disk (see writer.py)
    /integrity/set_crc32    uint32 (n_sets,): CRC-32 of each set's pixels, set_index, frame columns, metadata
    /integrity/result_crc32 uint32 (n_results,): CRC-32 of each result row (see :func:`result_row_crc32`)
    /sets/pixels            (n_sets, frames_per_set, rows, cols), frame dtype, chunk = one set
    /sets/set_index         int64 (n_sets,)
    /sets/frame_id, /sets/host_time_ns, /sets/device_timestamp      int64 (n_sets, frames_per_set)
    /sets/metadata/<key>    float64 (n_sets, frames_per_set), NaN where a frame lacks the key
    /apertures/mask         bool (n_apertures, rows, cols); /apertures/from_set int64 (n_apertures,)
    /results/<key>          (n_results, *shape) bool, int64, float64 or complex128
    /results/<key>/utf8, /results/<key>/end   a string column: UTF-8 bytes and each row's end offset

Version 3 adds the result columns of the data-quality mask and the robust figures: ``pv``,
``pvr`` and ``quality_inside``, ``quality_used``, ``quality_low_modulation``,
``quality_saturated``, ``quality_untrusted_order``, ``quality_clipped``, ``quality_rim`` (pixels of
the fit grid), and the live surface figures with ``[surface]`` on: ``surface_sag_nm``,
``surface_irr_nm``, ``surface_rsi_nm``, ``surface_rmst_nm``, ``surface_rmsi_nm``, ``surface_rmsa_nm``,
``surface_pvr_nm`` (nm of surface, NaN where not measured), ``spec_passed`` (1, 0, -1: no verdict)
and ``spec_limiting`` (the drawing's quantity nearest its limit);
its integrity is version 2's. Versions 1 and 2 still read (without those columns).

Strings are stored as UTF-8 bytes plus end offsets rather than HDF5 variable-length strings,
because variable-length data lives in the global heap, which SWMR does not cover.

Integrity (versions 2 and 3)
----------------------------
Three layers, because each misses something the others catch:

- HDF5 checks its own metadata (``libver="latest"``: superblock, object headers and chunk
  indexes carry lookup3 checksums), so a damaged header or index is an error, never silent.
- Pixels: a CRC-32 per set (``/integrity/set_crc32``, :func:`set_crc32`) over the set's pixels,
  set index, frame columns and metadata row, computed by the writer from the values it stores and
  checked by the reader on the values it reads back, one set at a time (a pixel chunk is one set).
  Not HDF5's ``fletcher32`` filter: it accepts an all-zero chunk (stored and computed sums are both
  0), which is what a truncated file or a zeroed disk block reads as, and it is slow: measured on a
  5 x 1024 x 1024 uint16 set, writing took ~45 ms more per set with it, ~15 ms more with the CRC
  (``zlib.crc32`` of zeros is never 0).
- Every other dataset is chunked (``committed_counts`` too, for this) and carries ``fletcher32``:
  a bit flip in a chunk fails its read. These chunks are small (``_CHUNK_BYTES``, 64 KiB), so a
  flip costs at most one chunk of rows; result rows also carry a CRC-32 each
  (``/integrity/result_crc32``, :func:`result_row_crc32`), which catches zeroed chunks.
- The root attribute ``header_crc32`` covers the configuration and the conventions
  (:func:`header_crc32`), and ``/integrity`` attribute ``layout_crc32`` the names, kinds and
  shapes of the result columns and the metadata keys (:func:`layout_crc32`): HDF5 keeps more than
  8 attributes or links of a group in a fractal heap whose blocks carry no checksum by default.
  ``layout_crc32`` is written when SWMR starts (both are known then), or at ``close``.

A truncated file is also caught before any checksum: the reader compares every chunk's extent
with the file's real size (see :func:`read_rows` and :mod:`wavestack.pipeline.formats.hdf5_open`).

A version 1 recording (no checksums) still reads: HDF5's metadata checksums and the reader's
end-of-file check on every chunk still catch truncation, but a flipped pixel byte cannot be
detected; the reader says so in :attr:`RecordingReader.notes`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final, Union

import json
import zlib

import h5py
import numpy as np
from numpy.typing import DTypeLike, NDArray

from wavestack.pipeline.formats import InputError, check_allocation

FORMAT_NAME: Final = "wavestack-recording"
FORMAT_VERSION: Final = 3
#: Versions this wavestack reads (1: no checksums; 2: no quality columns).
READABLE_VERSIONS: Final = (1, 2, 3)
_FRAME_COLUMNS: Final = ("frame_id", "host_time_ns", "device_timestamp")
_CHUNK_BYTES: Final = 1 << 16  # target size of a chunk of small per-row columns (a bit flip costs one chunk)
_KIND_RANK: Final = ("bool", "int", "float", "complex")  # a column accepts its kind and those before it
_KIND_DTYPES: Final = (np.bool_, np.int64, np.float64, np.complex128)

#: One value of a result row: a number, a bool, a string or a numeric array (e.g. the coefficients).
RowValue = Union[bool, int, float, complex, str, NDArray[Any]]
#: A result row: column name -> value. The first row (or the template) fixes the columns.
ResultRow = Mapping[str, RowValue]


# -- storage helpers ----------------------------------------------------------------------------
def _growable(group: h5py.Group, name: str, row_shape: tuple[int, ...], dtype: DTypeLike) -> h5py.Dataset:
    """An empty dataset that grows along axis 0, chunked to about ``_CHUNK_BYTES``."""
    row_bytes = max(1, int(np.prod(row_shape, dtype=np.int64)) * np.dtype(dtype).itemsize)
    rows = max(1, min(1024, _CHUNK_BYTES // row_bytes))
    return group.create_dataset(name, shape=(0, *row_shape), maxshape=(None, *row_shape),
                                chunks=(rows, *row_shape), dtype=dtype, fletcher32=True)


def header_crc32(attrs: Mapping[str, Any], conventions: Mapping[str, Any]) -> int:
    """CRC-32 of the root attributes a replay depends on and of the conventions (canonical JSON)."""
    keys = ("format", "format_version", "software_version", "config_toml", "created_utc")
    header = {k: _plain(attrs.get(k)) for k in keys} | {"conventions": {k: _plain(v) for k, v in conventions.items()}}
    return zlib.crc32(json.dumps(header, sort_keys=True).encode("utf-8"))


def layout_crc32(result_columns: Sequence[_Column], metadata_keys: Sequence[str]) -> int:
    """CRC-32 of the result columns (names, kinds, shapes) and frame-metadata keys, in order.

    HDF5 keeps the links of a group with more than 8 members in a fractal heap whose blocks carry
    no checksum by default, so a changed column name would otherwise pass unnoticed.
    """
    layout = {"results": [[c.key, c.kind, list(c.shape)] for c in result_columns], "metadata": list(metadata_keys)}
    return zlib.crc32(json.dumps(layout).encode("utf-8"))


def set_crc32(pixels: NDArray[Any], set_index: int, frame_columns: Sequence[NDArray[np.int64]],
              metadata: Sequence[NDArray[np.float64]]) -> int:
    """CRC-32 of one set as stored: pixels (stored dtype), set index, frame columns, metadata rows."""
    crc = zlib.crc32(np.ascontiguousarray(pixels).tobytes())
    crc = zlib.crc32(np.int64(set_index).tobytes(), crc)
    for column in (*frame_columns, *metadata):
        crc = zlib.crc32(np.ascontiguousarray(column).tobytes(), crc)
    return crc


def result_row_crc32(values: Sequence[bytes | NDArray[Any]]) -> int:
    """CRC-32 of one result row as stored: each column's value in column order (strings as UTF-8)."""
    crc = 0
    for value in values:
        data = value if isinstance(value, bytes) else np.ascontiguousarray(value).tobytes()
        crc = zlib.crc32(len(data).to_bytes(8, "little") + data, crc)
    return crc


def _plain(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    return value.item() if isinstance(value, np.generic) else value


def _append_rows(columns: Sequence[tuple[h5py.Dataset, Any]], row: int) -> None:
    """Write ``value`` as row ``row`` of each dataset, growing it by one row."""
    for dataset, value in columns:
        dataset.resize(row + 1, axis=0)
        dataset[row] = value


def _column_name_ok(key: object) -> bool:
    """HDF5 link names: non-empty, and no '/' (it would nest groups)."""
    return isinstance(key, str) and bool(key) and "/" not in key


def _columns_of(record: ResultRow) -> tuple[_Column, ...]:
    """Result columns named, typed and shaped after ``record``."""
    if not record:
        raise ValueError("result record: expected at least one column, got an empty record")
    return tuple(_Column.of(key, value) for key, value in record.items())


def _numeric_kind(dtype: np.dtype[Any]) -> str | None:
    return {"b": "bool", "i": "int", "u": "int", "f": "float", "c": "complex"}.get(dtype.kind)


@dataclass(frozen=True)
class _Column:
    """One result column: name, kind ("str" or one of ``_KIND_RANK``) and per-row shape."""

    key: str
    kind: str
    shape: tuple[int, ...]

    @classmethod
    def of(cls, key: str, value: Any) -> _Column:
        if not _column_name_ok(key):
            raise ValueError(f"result column {key!r}: names must be non-empty strings without '/'")
        if isinstance(value, str):
            return cls(key, "str", ())
        kind, array = None, None
        if not isinstance(value, (bytes, bytearray)) and value is not None:
            try:
                array = np.asarray(value)
            except ValueError:  # ragged sequence
                pass
            kind = None if array is None else _numeric_kind(array.dtype)
        if kind is None or array is None:
            raise ValueError(f"result column {key!r}: expected bool, int, float, complex, str or a numeric "
                             f"array, got {type(value).__name__}")
        return cls(key, kind, array.shape)

    def prepare(self, value: Any) -> bytes | NDArray[Any]:
        """``value`` encoded for this column (UTF-8 bytes or an array of the column dtype)."""
        if self.kind == "str":
            if not isinstance(value, str):
                raise ValueError(f"result column {self.key!r}: expected str, got {type(value).__name__}")
            try:
                return value.encode("utf-8")
            except UnicodeEncodeError as error:
                raise ValueError(f"result column {self.key!r}: not encodable as UTF-8 ({error.reason})") from error
        other = _Column.of(self.key, value) if not isinstance(value, str) else _Column(self.key, "str", ())
        if other.kind == "str" or _KIND_RANK.index(other.kind) > _KIND_RANK.index(self.kind):
            raise ValueError(f"result column {self.key!r}: expected {self.kind}, got {other.kind} "
                             f"({type(value).__name__})")
        if other.shape != self.shape:
            raise ValueError(f"result column {self.key!r}: expected shape {self.shape}, got {other.shape}")
        return np.asarray(value).astype(_KIND_DTYPES[_KIND_RANK.index(self.kind)])


class _ResultColumns:
    """The result table: one growable dataset per column; a string column is a group of UTF-8
    bytes (``utf8``) and each row's end offset into them (``end``)."""

    def __init__(self, group: h5py.Group, columns: tuple[_Column, ...], n_rows: int) -> None:
        self._group = group
        self._columns = columns
        self.n_rows = n_rows
        # bytes of each string column so far; only the writer appends, and it starts from 0 rows
        self._text_bytes = {c.key: 0 for c in columns if c.kind == "str"}

    @classmethod
    def create(cls, group: h5py.Group, columns: tuple[_Column, ...]) -> _ResultColumns:
        """Empty datasets for ``columns`` in ``group``."""
        for column in columns:
            if column.kind == "str":
                text = group.create_group(column.key)
                _growable(text, "utf8", (), np.uint8)
                _growable(text, "end", (), np.int64)
            else:
                _growable(group, column.key, column.shape, _KIND_DTYPES[_KIND_RANK.index(column.kind)])
        return cls(group, columns, 0)

    @classmethod
    def open(cls, group: h5py.Group, committed: int) -> _ResultColumns:
        """The columns of a recorded table, trusting at most ``committed`` rows.

        Raises
        ------
        ValueError
            A column that is not a numeric dataset of ndim >= 1 nor a string group (``utf8``, ``end``).
        """
        columns, lengths = [], [committed]
        for key, node in group.items():
            if isinstance(node, h5py.Group):
                utf8, end = node.get("utf8"), node.get("end")
                if not (isinstance(utf8, h5py.Dataset) and isinstance(end, h5py.Dataset) and utf8.ndim == 1
                        and end.ndim == 1 and utf8.dtype == np.uint8 and end.dtype.kind in "iu"):
                    raise ValueError(f"result column {key!r}: expected a string column (uint8 'utf8' and integer "
                                     "'end', both 1-D)")
                columns.append(_Column(key, "str", ()))
                lengths.append(len(end))
            else:
                kind = _numeric_kind(node.dtype) if isinstance(node, h5py.Dataset) else None
                if kind is None or node.ndim < 1:
                    raise ValueError(f"result column {key!r}: expected a numeric dataset with one row per result, "
                                     f"got {getattr(node, 'dtype', type(node).__name__)} {getattr(node, 'shape', '')}")
                columns.append(_Column(key, kind, tuple(node.shape[1:])))
                lengths.append(len(node))
        return cls(group, tuple(columns), min(lengths))

    @property
    def columns(self) -> tuple[_Column, ...]:
        return self._columns

    def append(self, record: ResultRow, row: int) -> int:
        """Validate the whole ``record`` against the columns, write it as row ``row``; its CRC-32."""
        known = {c.key for c in self._columns}
        for key in [*(k for k in record if k not in known), *(k for k in known if k not in record)]:
            state = "is not a column" if key not in known else "is missing"
            raise ValueError(f"result record: key {key!r} {state}; the columns are fixed by the first record: "
                             f"{sorted(known)}")
        values = [(column, column.prepare(record[column.key])) for column in self._columns]
        for column, value in values:
            if isinstance(value, bytes):
                text = self._group[column.key]
                start, stop = self._text_bytes[column.key], self._text_bytes[column.key] + len(value)
                if value:
                    text["utf8"].resize(stop, axis=0)
                    text["utf8"][start:stop] = np.frombuffer(value, np.uint8)
                _append_rows([(text["end"], stop)], row)
                self._text_bytes[column.key] = stop
            else:
                _append_rows([(self._group[column.key], value)], row)
        self.n_rows = row + 1
        return result_row_crc32([value for _, value in values])

    def read(self, file_bytes: int) -> ResultTable:
        """Every column, ``n_rows`` long, with the rows that could not be read marked (see :class:`ResultTable`)."""
        table: dict[str, NDArray[Any]] = {}
        raw: dict[str, list[bytes]] = {}
        ok = np.ones(self.n_rows, bool)
        reasons: list[str] = []
        for column in self._columns:
            node = self._group[column.key]
            if column.kind != "str":
                table[column.key], rows_ok, why = read_rows(node, self.n_rows, file_bytes)
            else:
                raw[column.key], rows_ok, why = _read_text(node, self.n_rows, file_bytes)
                texts = np.empty(self.n_rows, dtype=object)  # not numpy str: that would strip trailing NULs
                texts[:] = [data.decode("utf-8", "replace") for data in raw[column.key]]
                table[column.key] = texts
            if why:
                reasons.append(f"column {column.key!r} {why}")
            ok &= rows_ok
        return ResultTable(table, raw, ok, "; ".join(reasons))


@dataclass(frozen=True)
class ResultTable:
    """The result table as read: ``columns`` (key -> (n_rows, *shape) arrays, strings as ``str``),
    ``text`` (the UTF-8 bytes of string columns), ``ok`` (bool (n_rows,): every column of the row
    was read) and ``reason`` (why rows are not ok, "" if all are)."""

    columns: dict[str, NDArray[Any]]
    text: dict[str, list[bytes]]
    ok: NDArray[np.bool_]
    reason: str

    def row_crc32(self, row: int) -> int:
        """The CRC-32 of row ``row`` as the writer computed it (:func:`result_row_crc32`)."""
        return result_row_crc32([self.text[key][row] if key in self.text else values[row]
                                 for key, values in self.columns.items()])


def _read_text(group: h5py.Group, n_rows: int, file_bytes: int) -> tuple[list[bytes], NDArray[np.bool_], str]:
    """The first ``n_rows`` strings of a string column, and which rows were read intact."""
    ends, ok, why = read_rows(group["end"], n_rows, file_bytes)
    utf8 = group["utf8"]
    size = int(min(len(utf8), max(ends.max(initial=0), 0)))
    data, byte_ok, byte_why = read_rows(utf8, size, file_bytes)
    starts = np.concatenate(([0], ends[:-1]))
    texts: list[bytes] = []
    for row, (start, end) in enumerate(zip(starts.tolist(), ends.tolist())):
        if not 0 <= start <= end <= size:
            ok[row] = False
            why = why or f"has string offsets out of order or beyond its {size} bytes"
        elif not byte_ok[start:end].all():
            ok[row] = False
            why = why or byte_why
        texts.append(data[start:end].tobytes() if ok[row] else b"")
    return texts, ok, why


def read_rows(dataset: h5py.Dataset, n_rows: int, file_bytes: int) -> tuple[NDArray[Any], NDArray[np.bool_], str]:
    """Rows ``[0, n_rows)`` of ``dataset``, one chunk at a time, and which rows were read intact.

    A chunk is damaged when its bytes lie beyond the end of the file (``file_bytes``: a truncated
    file reads as zeros there) or when HDF5 fails to read it (a ``fletcher32`` or metadata checksum
    mismatch). Damaged rows are zeros in the returned array. Before anything is allocated the rows
    are checked against what the file holds (:func:`check_declared_rows`).

    Returns
    -------
    values : ndarray, (n_rows, *dataset.shape[1:])
    ok : ndarray of bool, (n_rows,)
    reason : str
        Why the first damaged chunk is damaged; "" if none is.

    Raises
    ------
    InputError
        Rows the file does not hold, or more than the memory budget.
    """
    n_rows = max(0, min(n_rows, len(dataset)))
    check_declared_rows(dataset, n_rows)
    values = np.zeros((n_rows, *dataset.shape[1:]), dataset.dtype)
    ok = np.ones(n_rows, bool)
    step = dataset.chunks[0] if dataset.chunks else max(1, n_rows)
    reason = ""
    for start in range(0, n_rows, step):
        stop = min(n_rows, start + step)
        why = _chunk_damage(dataset, start, file_bytes)
        if not why:
            try:
                values[start:stop] = dataset[start:stop]
            except (OSError, RuntimeError) as error:  # a checksum mismatch, or metadata beyond the end of the file
                why = f"fails its checksum ({error})" if "filter" in str(error) else f"is unreadable ({error})"
        if why:
            ok[start:stop] = False
            reason = reason or f"rows {start}-{stop - 1} {why}"
    return values, ok, reason


def check_declared_rows(dataset: h5py.Dataset, n_rows: int) -> None:
    """Refuse to read ``n_rows`` rows that the file does not hold, or that exceed the memory budget.

    A dataset's length is only a declaration: a few megabytes of HDF5 can declare 2e8 rows whose
    chunks were never written (they would read as zeros, 50 GB of them). The writer writes every
    row it commits, so the chunks a dataset holds (in the file's chunk index, also when their
    bytes lie beyond a truncated end) must cover the rows to be read; a truncated file's rows are
    damaged rows, never a refusal. Then the rows must fit the memory budget
    (:func:`~wavestack.pipeline.formats.limits.check_allocation`).

    Raises
    ------
    InputError
        Naming the file, the dataset and what it declares.
    """
    path, name = dataset.file.filename, dataset.name
    if n_rows and dataset.chunks:
        try:
            covered = dataset.id.get_num_chunks() * dataset.chunks[0]
        except (OSError, RuntimeError, ValueError) as error:  # an unreadable chunk index: damage, found per chunk
            covered, _ = n_rows, error
        if covered < n_rows:
            raise InputError(f"{path}: malformed wavestack recording: {name} declares {n_rows} rows but its "
                             f"chunks hold at most {covered}; a recorder writes every row it declares")
    check_allocation(path, f"dataset {name}", (n_rows, *dataset.shape[1:]), dataset.dtype.itemsize)


def _chunk_damage(dataset: h5py.Dataset, row: int, file_bytes: int) -> str:
    """Why the chunk holding ``row`` cannot be trusted ("" if it can be read)."""
    if not dataset.chunks:
        return ""
    try:
        info = dataset.id.get_chunk_info_by_coord((row - row % dataset.chunks[0],) + (0,) * (dataset.ndim - 1))
    except (OSError, RuntimeError, ValueError, KeyError) as error:  # h5py raises RuntimeError for some
        return f"is unreadable (its chunk index: {error})"
    if info.byte_offset is not None and info.byte_offset + info.size > file_bytes:
        return f"lies beyond the end of the file ({file_bytes} bytes): truncated"
    return ""
