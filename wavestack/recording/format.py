"""The on-disk format of a station recording: names, layout and the result table.

Shared by :mod:`wavestack.recording.writer` and :mod:`wavestack.recording.reader`
(both re-exported by :mod:`wavestack.recording`).

Layout (``format_version`` 1)::

    /                       attrs: format, format_version, software_version, config_toml, created_utc
    /conventions            attrs: one per convention (str, int or float)
    /committed_counts       int64 (3,): sets, apertures, results durable on disk (see writer.py)
    /sets/pixels            (n_sets, frames_per_set, rows, cols), frame dtype, chunk = one set
    /sets/set_index         int64 (n_sets,)
    /sets/frame_id, /sets/host_time_ns, /sets/device_timestamp      int64 (n_sets, frames_per_set)
    /sets/metadata/<key>    float64 (n_sets, frames_per_set), NaN where a frame lacks the key
    /apertures/mask         bool (n_apertures, rows, cols); /apertures/from_set int64 (n_apertures,)
    /results/<key>          (n_results, *shape) bool, int64, float64 or complex128
    /results/<key>/utf8, /results/<key>/end   a string column: UTF-8 bytes and each row's end offset

Strings are stored as UTF-8 bytes plus end offsets rather than HDF5 variable-length strings,
because variable-length data lives in the global heap, which SWMR does not cover.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final, Union

import h5py
import numpy as np
from numpy.typing import DTypeLike, NDArray

FORMAT_NAME: Final = "wavestack-recording"
FORMAT_VERSION: Final = 1
_FRAME_COLUMNS: Final = ("frame_id", "host_time_ns", "device_timestamp")
_CHUNK_BYTES: Final = 1 << 20  # target size of a chunk of small per-row columns
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
    rows = max(1, min(4096, _CHUNK_BYTES // row_bytes))
    return group.create_dataset(name, shape=(0, *row_shape), maxshape=(None, *row_shape),
                                chunks=(rows, *row_shape), dtype=dtype)


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
        self._text_bytes = {c.key: int(group[c.key]["end"][n_rows - 1]) if n_rows else 0
                            for c in columns if c.kind == "str"}

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
        """The columns of a recorded table, trusting at most ``committed`` rows."""
        columns, lengths = [], [committed]
        for key, node in group.items():
            if isinstance(node, h5py.Group):
                columns.append(_Column(key, "str", ()))
                lengths.append(len(node["end"]))
            else:
                kind = _numeric_kind(node.dtype)
                if kind is None:
                    raise ValueError(f"result column {key!r} has unsupported dtype {node.dtype}")
                columns.append(_Column(key, kind, tuple(node.shape[1:])))
                lengths.append(len(node))
        return cls(group, tuple(columns), min(lengths))

    def append(self, record: ResultRow, row: int) -> None:
        """Validate the whole ``record`` against the columns, then write it as row ``row``."""
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

    def read(self) -> dict[str, NDArray[Any]]:
        """Every column, ``n_rows`` long; string columns as object arrays of ``str``."""
        table: dict[str, NDArray[Any]] = {}
        for column in self._columns:
            node = self._group[column.key]
            if column.kind != "str":
                table[column.key] = node[: self.n_rows]
                continue
            ends = node["end"][: self.n_rows]
            data = node["utf8"][: int(ends[-1])].tobytes() if self.n_rows else b""
            starts = np.concatenate(([0], ends[:-1]))
            texts = np.empty(len(ends), dtype=object)  # not numpy str: that would strip trailing NULs
            texts[:] = [data[a:b].decode("utf-8") for a, b in zip(starts, ends)]
            table[column.key] = texts
        return table
