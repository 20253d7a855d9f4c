"""The results of a campaign on disk: Parquet files, one per recording, written only by the client.

Layout of ``--out RESULTS`` (a directory)::

    RESULTS/results/<name>-<key>.parquet     one row per result (:class:`~wavestack.batch.rows.ResultRow`)
    RESULTS/summaries/<name>-<key>.parquet   one row: the recording's summary (:class:`RecordingSummary`)
    RESULTS/settings.parquet                 settings_hash -> the configuration used (TOML, or "recorded")

``key`` is the file's SHA-256 and the settings hash (16 hex digits each). Why Parquet, one file
per recording: the table is columnar and typed (a coefficient vector is a list<double> column,
read in one call by pyarrow, pandas, polars or DuckDB, the whole directory as one table), and a
finished Parquet file is never appended to: its footer is written last, so a file being appended
to when the process dies is lost whole. Each recording's file is instead written complete under a
temporary name, flushed and renamed (atomic on POSIX), rows first and summary second, so the
summary is the commit mark: a crash loses at most the recordings in flight, never a written one.
The summary commits to its rows: it holds their count and the SHA-256 of the rows file, and
``--resume`` trusts exactly the recordings whose summary and rows file agree (a rows file deleted,
replaced or garbled since is analysed again; :meth:`ResultsStore.committed`). HDF5 would also be
typed, but a crash while appending to one shared file can damage what it already holds.
"""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from wavestack.batch.rows import ResultRow
from wavestack.pipeline import InputError

_STR, _I64, _F64, _BOOL = pa.string(), pa.int64(), pa.float64(), pa.bool_()
_KINDS = {"str": _STR, "int": _I64, "float": _F64, "bool": _BOOL, "tuple[int, ...]": pa.list_(_I64),
          "tuple[float, ...]": pa.list_(_F64)}


@dataclass(frozen=True)
class RecordingSummary:
    """One recording's outcome (a row of the summaries table).

    Attributes
    ----------
    recording : str
    file_sha256, settings_hash : str
        The resume key.
    kind : str
        "station", "polish", "unsupported" or "unreadable".
    status : str
        "ok", "damaged" (readable part analysed), "skipped" (nothing to analyse: see ``message``).
    sets, results, valid, skipped : int
        Sets in the file, rows written, valid rows, damaged sets not analysed.
    max_difference_rms : float
        Largest difference from the recorded coefficients, waves (NaN when none compared).
    damage, notes, message : str
        The reader's damage report and notes ("; "-joined), and why a file was skipped.
    phase_s, aperture_s, unwrap_s, fit_s, wall_s : float
        Seconds spent per stage and in the tasks, summed (measurements, not results).
    rows_sha256 : str
        SHA-256 of the recording's rows file as committed ("" until it is written); with
        ``results`` (its row count), what the summary commits to.
    """

    recording: str
    file_sha256: str
    settings_hash: str
    kind: str
    status: str
    sets: int
    results: int
    valid: int
    skipped: int
    max_difference_rms: float
    damage: str
    notes: str
    message: str
    phase_s: float
    aperture_s: float
    unwrap_s: float
    fit_s: float
    wall_s: float
    rows_sha256: str = ""


def _schema(cls: type) -> pa.Schema:
    return pa.schema([(f.name, _KINDS[str(f.type)]) for f in fields(cls)])


ROW_SCHEMA = _schema(ResultRow)
SUMMARY_SCHEMA = _schema(RecordingSummary)
_SETTINGS_SCHEMA = pa.schema([("settings_hash", _STR), ("config_toml", _STR)])


class ResultsStore:
    """The ``--out`` directory (module notes); only the client process writes it.

    Example
    -------
    >>> import tempfile
    >>> store = ResultsStore(Path(tempfile.mkdtemp()) / "out")
    >>> store.done_keys()
    set()
    """

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        if self.root.exists() and not self.root.is_dir():
            raise InputError(f"{self.root}: --out must be a directory (it exists and is a file)")

    def has_results(self) -> bool:
        return any(self._dir("summaries").glob("*.parquet")) if (self.root / "summaries").is_dir() else False

    def done_keys(self) -> set[tuple[str, str]]:
        """(file_sha256, settings_hash) of every committed recording (:meth:`committed`)."""
        return {(s.file_sha256, s.settings_hash) for s in self.committed()}

    def committed(self) -> list[RecordingSummary]:
        """The summaries whose rows file is there and is what they commit to (row count and SHA-256)."""
        return [summary for summary, _ in self._committed_files()]

    def _committed_files(self) -> list[tuple[RecordingSummary, Path]]:
        found = []
        for path in sorted((self.root / "summaries").glob("*.parquet")):
            rows = self.root / "results" / path.name
            for summary in _read_summaries(path):
                if summary.rows_sha256 and _sha256(rows) == summary.rows_sha256 and _row_count(rows) == summary.results:
                    found.append((summary, rows))
        return found

    def write_settings(self, settings_hash: str, config_toml: str | None) -> None:
        """Add a settings row unless present (the small table is rewritten atomically)."""
        path = self.root / "settings.parquet"
        table = pq.read_table(path) if path.exists() else _SETTINGS_SCHEMA.empty_table()
        if settings_hash in table.column("settings_hash").to_pylist():
            return
        row = pa.Table.from_pylist([{"settings_hash": settings_hash,
                                     "config_toml": "recorded" if config_toml is None else config_toml}],
                                   schema=_SETTINGS_SCHEMA)
        self._write_atomic(pa.concat_tables([table, row]), path)

    def write_recording(self, name_key: str, rows: Sequence[ResultRow], summary: RecordingSummary) -> RecordingSummary:
        """Commit one recording: its rows, then its summary with their count and SHA-256 (each file
        written whole, then renamed); returns the summary as committed."""
        base = _safe_name(name_key)
        table = pa.Table.from_pylist([asdict(r) for r in rows], schema=ROW_SCHEMA)
        rows_path = self._dir("results") / f"{base}.parquet"
        self._write_atomic(table, rows_path)
        summary = replace(summary, results=len(rows), rows_sha256=_sha256(rows_path))
        self._write_atomic(pa.Table.from_pylist([asdict(summary)], schema=SUMMARY_SCHEMA),
                           self._dir("summaries") / f"{base}.parquet")
        return summary

    def read_rows(self) -> pa.Table:
        """Every committed recording's rows (:meth:`committed`), one table, sorted by recording and position."""
        tables = [pq.read_table(rows, schema=ROW_SCHEMA) for _, rows in self._committed_files()]
        table = pa.concat_tables(tables) if tables else ROW_SCHEMA.empty_table()
        return table.sort_by([("recording", "ascending"), ("position", "ascending")])

    def _dir(self, name: str) -> Path:
        path = self.root / name
        path.mkdir(parents=True, exist_ok=True)
        return path

    @staticmethod
    def _write_atomic(table: pa.Table, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        pq.write_table(table, temporary)
        with open(temporary, "rb+") as stream:
            os.fsync(stream.fileno())
        os.replace(temporary, path)
        directory = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(directory)
        finally:
            os.close(directory)


def _read_summaries(path: Path) -> list[RecordingSummary]:
    try:
        return [RecordingSummary(**r) for r in pq.read_table(path, schema=SUMMARY_SCHEMA).to_pylist()]
    except (OSError, pa.ArrowException, TypeError):
        return []


def _sha256(path: Path) -> str:
    """SHA-256 (hex) of a file's bytes, "" when it cannot be read."""
    try:
        with open(path, "rb") as stream:
            return hashlib.file_digest(stream, "sha256").hexdigest()
    except OSError:
        return ""


def _row_count(path: Path) -> int:
    """Rows of a Parquet file (its footer), -1 when it is not one."""
    try:
        return int(pq.ParquetFile(path).metadata.num_rows)
    except (OSError, pa.ArrowException):
        return -1


def _safe_name(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text)[-120:]
