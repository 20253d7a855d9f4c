"""The simulated machine's own reader of job files (written apart from the host's writer on purpose).

Re-implemented from the job-file description in the README (the host's writer lives in the driver,
which a simulator never imports): a UTF-8 JSON body, a newline, and a trailer line
``wsjob-crc32 XXXXXXXX N`` holding the CRC-32 (zlib's) of the body's ``N`` bytes, followed by
`` hmac-sha256 H`` (the body's HMAC-SHA256 under the job key, 64 hex digits) when the host has a
key. The reader checks, in this order, and refuses with the first reason that applies:

1. the file exists, is a regular file (a FIFO or a device is never waited on or read), and is not
   larger than the machine takes (FILE_MISSING, TOO_MANY_POINTS);
2. the trailer is there and the body is as long as it says (FILE_TRUNCATED);
3. the body's CRC-32 equals the trailer's (FILE_CORRUPT); with a machine key, the trailer's HMAC
   is the body's under that key (NOT_SIGNED: missing or wrong);
4. the body is a JSON object of format ``wavestack-polishing-job`` version 1 (FILE_CORRUPT,
   UNSUPPORTED_FORMAT) with an integer ``job_id``, ``point_count``, a number ``total_dwell_s``, the
   columns ``x_mm y_mm dwell_s feed_mm_s`` and one row of four finite numbers per point
   (FILE_CORRUPT, COUNT_MISMATCH when the rows disagree with ``point_count``).

It never raises anything but :class:`JobFileRefused`.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import math
import os
import re
import stat
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from wavestack.simulators.plc.job_state import StopReason

__all__ = ["JobFileRefused", "MachineJob", "read_job_file", "read_key_file"]

_FORMAT, _VERSION = "wavestack-polishing-job", 1
_COLUMNS = ["x_mm", "y_mm", "dwell_s", "feed_mm_s"]
_TRAILER = re.compile(rb"\nwsjob-crc32 ([0-9a-f]{8}) (\d{1,12})(?: hmac-sha256 ([0-9a-f]{64}))?\n\Z")


class JobFileRefused(Exception):
    """The machine refuses a job file; :attr:`reason` is the code it reports."""

    def __init__(self, reason: StopReason, message: str) -> None:
        super().__init__(f"{reason.name}: {message}")
        self.reason = reason
        self.message = message

    def __reduce__(self) -> tuple[type[JobFileRefused], tuple[StopReason, str]]:
        return JobFileRefused, (self.reason, self.message)  # it crosses from the machine's reading process


@dataclass(frozen=True)
class MachineJob:
    """A job as the machine read it (arrays shape (K,), read-only; mm, s, mm/s)."""

    job_id: int
    crc32: int
    total_dwell_s: float
    x_mm: NDArray[np.float64] = field(repr=False)
    y_mm: NDArray[np.float64] = field(repr=False)
    dwell_s: NDArray[np.float64] = field(repr=False)
    feed_mm_s: NDArray[np.float64] = field(repr=False)

    @property
    def point_count(self) -> int:
        """Points K."""
        return int(self.dwell_s.size)


def read_job_file(path: Path, max_bytes: int, key: bytes | None = None) -> MachineJob:
    """Read and check one job file.

    Parameters
    ----------
    path
        The file (``job-NNNNN.wsjob`` in the machine's job folder).
    max_bytes
        The largest file the machine reads.
    key
        The machine's job key: only a file whose trailer carries the body's HMAC under it is read.

    Raises
    ------
    JobFileRefused
        See the module docstring for the reasons, in order.
    """
    data = _read_bytes(path, max_bytes)
    match = _TRAILER.search(data)
    if match is None:
        raise JobFileRefused(StopReason.FILE_TRUNCATED, f"{path.name}: no CRC trailer at the end "
                             f"({len(data)} bytes)")
    body = data[:match.start()]
    if len(body) != int(match.group(2)):
        raise JobFileRefused(StopReason.FILE_TRUNCATED, f"{path.name}: the body has {len(body)} bytes, "
                             f"the trailer says {int(match.group(2))}")
    crc = zlib.crc32(body) & 0xFFFFFFFF
    if crc != int(match.group(1), 16):
        raise JobFileRefused(StopReason.FILE_CORRUPT, f"{path.name}: body CRC-32 {crc:08x}, trailer says "
                             f"{match.group(1).decode()}")
    if key is not None:
        expected = hmac.new(key, body, hashlib.sha256).hexdigest().encode("ascii")
        if match.group(3) is None or not hmac.compare_digest(expected, match.group(3)):
            raise JobFileRefused(StopReason.NOT_SIGNED, f"{path.name}: the trailer carries "
                                 f"{'no' if match.group(3) is None else 'a wrong'} HMAC-SHA256 for the machine's key")
    try:
        document = json.loads(body.decode("utf-8"), parse_constant=_no_constant)
    except (UnicodeDecodeError, ValueError, RecursionError) as error:
        raise JobFileRefused(StopReason.FILE_CORRUPT, f"{path.name}: not a JSON document ({error})") from None
    return _parse(path.name, document, crc)


def _read_bytes(path: Path, max_bytes: int) -> bytes:
    try:  # O_NONBLOCK: opening a FIFO returns at once (no writer needed), and fstat says what it is
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
        with open(descriptor, "rb", closefd=True) as stream:
            info = os.fstat(stream.fileno())
            if not stat.S_ISREG(info.st_mode):
                raise JobFileRefused(StopReason.FILE_MISSING, f"{path.name}: not a regular file (a FIFO, device "
                                     "or folder is never read as a job)")
            if info.st_size > max_bytes:
                raise JobFileRefused(StopReason.TOO_MANY_POINTS, f"{path.name}: {info.st_size} bytes, the machine "
                                     f"reads at most {max_bytes}")
            return stream.read(max_bytes + 1)
    except FileNotFoundError:
        raise JobFileRefused(StopReason.FILE_MISSING, f"no file {path.name} in {path.parent}") from None
    except OSError as error:
        raise JobFileRefused(StopReason.FILE_MISSING, f"{path.name}: cannot read it ({error})") from None


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number the machine takes")


def _finite(value: object) -> bool:
    """A JSON number the machine takes: a finite float, or an int within the float range (not a bool)."""
    if isinstance(value, bool):
        return False
    if isinstance(value, int):
        return -1e300 < value < 1e300
    return isinstance(value, float) and math.isfinite(value)


def _table(name: str, rows: list) -> NDArray[np.float64]:
    """The points as a (K, 4) array; fast path by numpy, the slow path only to name the first bad point."""
    try:
        kinds = {type(v) for row in rows for v in row} if all(type(row) is list for row in rows) else {None}
        table = np.array(rows, dtype=np.float64) if kinds <= {int, float} else None
    except (TypeError, ValueError, OverflowError):
        table = None
    if table is not None and table.shape == (len(rows), 4) and bool(np.all(np.isfinite(table))):
        return table
    for index, row in enumerate(rows):
        if not (isinstance(row, list) and len(row) == 4 and all(_finite(v) for v in row)):
            raise JobFileRefused(StopReason.FILE_CORRUPT, f"{name}: point {index} must be 4 finite numbers, "
                                 f"got {row!r:.60}")
    raise JobFileRefused(StopReason.FILE_CORRUPT, f"{name}: the points are not a table of 4 finite numbers per row")


def _integer(document: dict, key: str, name: str) -> int:
    value = document.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise JobFileRefused(StopReason.FILE_CORRUPT, f"{name}: {key} must be an integer, got {value!r:.40}")
    return value


def _parse(name: str, document: object, crc: int) -> MachineJob:
    if not isinstance(document, dict):
        raise JobFileRefused(StopReason.FILE_CORRUPT, f"{name}: the body is not a JSON object")
    if document.get("format") != _FORMAT or document.get("version") != _VERSION:
        raise JobFileRefused(StopReason.UNSUPPORTED_FORMAT, f"{name}: format {document.get('format')!r:.40} "
                             f"version {document.get('version')!r:.20}; expected {_FORMAT!r} version {_VERSION}")
    job_id, count = _integer(document, "job_id", name), _integer(document, "point_count", name)
    total = document.get("total_dwell_s")
    if not _finite(total):
        raise JobFileRefused(StopReason.FILE_CORRUPT, f"{name}: total_dwell_s must be a number, got {total!r:.40}")
    if document.get("columns") != _COLUMNS:
        raise JobFileRefused(StopReason.FILE_CORRUPT, f"{name}: columns must be {_COLUMNS}")
    rows = document.get("points")
    if not isinstance(rows, list) or not rows:
        raise JobFileRefused(StopReason.FILE_CORRUPT, f"{name}: points must be a non-empty list")
    if len(rows) != count:
        raise JobFileRefused(StopReason.COUNT_MISMATCH, f"{name}: {len(rows)} points, the header says {count}")
    table = _table(name, rows)
    table.setflags(write=False)
    return MachineJob(job_id=job_id, crc32=crc, total_dwell_s=float(total), x_mm=table[:, 0], y_mm=table[:, 1],
                      dwell_s=table[:, 2], feed_mm_s=table[:, 3])


def read_key_file(path: Path) -> bytes:
    """The machine's job key from a key file: hexadecimal text (at least 32 digits), whitespace around.

    Raises
    ------
    ValueError
        Unreadable, or not such a key.
    """
    try:
        key = bytes.fromhex(Path(path).read_text(encoding="ascii").strip())
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise ValueError(f"machine job key {path}: expected hexadecimal text ({error})") from None
    if len(key) < 16:
        raise ValueError(f"machine job key {path}: {len(key)} bytes; expected at least 16")
    return key
