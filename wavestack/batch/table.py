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
summary is the commit mark: a crash loses at most the recordings in flight, never a written one,
and ``--resume`` trusts exactly the recordings that have a summary. HDF5 would also be typed, but
a crash while appending to one shared file can damage what it already holds.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields
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
        """(file_sha256, settings_hash) of every recording with a summary (committed)."""
        return {(s.file_sha256, s.settings_hash) for s in self.summaries()}

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

    def write_recording(self, name_key: str, rows: Sequence[ResultRow], summary: RecordingSummary) -> None:
        """Commit one recording: its rows, then its summary (each file written whole, then renamed)."""
        base = _safe_name(name_key)
        table = pa.Table.from_pylist([asdict(r) for r in rows], schema=ROW_SCHEMA)
        self._write_atomic(table, self._dir("results") / f"{base}.parquet")
        self._write_atomic(pa.Table.from_pylist([asdict(summary)], schema=SUMMARY_SCHEMA),
                           self._dir("summaries") / f"{base}.parquet")

    def summaries(self) -> list[RecordingSummary]:
        """Every committed summary (unreadable leftovers of a crash are ignored)."""
        found = []
        for path in sorted((self.root / "summaries").glob("*.parquet")):
            try:
                found.extend(RecordingSummary(**r) for r in pq.read_table(path, schema=SUMMARY_SCHEMA).to_pylist())
            except (OSError, pa.ArrowException, TypeError):
                continue
        return found

    def read_rows(self) -> pa.Table:
        """Every committed recording's rows, one table, sorted by recording and position."""
        paths = [p for p in sorted((self.root / "results").glob("*.parquet"))
                 if (self.root / "summaries" / p.name).exists()]
        tables = [pq.read_table(p, schema=ROW_SCHEMA) for p in paths]
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


def _safe_name(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text)[-120:]
