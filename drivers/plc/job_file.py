"""The polishing job file the host hands to the machine, written atomically with a CRC-32.

Shop machines take NC programs as files; so does ours. The file ``job-NNNNN.wsjob`` (five-digit job
id) in the configured job folder is UTF-8 text in two parts:

1. the **body**, a JSON object, self-describing::

       {"format": "wavestack-polishing-job", "version": 1, "job_id": 42, "created_utc": "...",
        "units": {"position": "mm", "dwell": "s", "feed": "mm/s"},
        "frame": {"origin": "grid centre", "x": "right", "y": "up", "pixel_mm": 0.1,
                  "x_mm": "(col - (W - 1) / 2) * pixel_mm", "y_mm": "((H - 1) / 2 - row) * pixel_mm"},
        "tif": {...}, "aperture": {...}, "point_count": K, "total_dwell_s": T,
        "columns": ["x_mm", "y_mm", "dwell_s", "feed_mm_s"],
        "points": [[x, y, dwell, feed], ...]}

   one point per line; ``feed_mm_s[k]`` is the feed on the move into point ``k``; floats are
   written with Python's shortest round-trip repr, so the reader gets the writer's float64 exactly;
2. the **trailer**, one line after the body and a newline: ``wsjob-crc32 XXXXXXXX N`` with the
   CRC-32 (ISO-HDLC, as zlib and PKZIP compute it; 8 lowercase hex digits) of the body's ``N``
   bytes, and with a job key ``wsjob-crc32 XXXXXXXX N hmac-sha256 H`` where ``H`` is the
   HMAC-SHA256 (RFC 2104) of the body under the key, 64 lowercase hex digits. A reader that finds
   no trailer knows the file is truncated; one whose body does not match knows it is corrupt. The
   same CRC-32 is announced over Modbus, so the machine also knows it reads the file the host
   meant. The CRC-32 catches accidents, not tampering: anyone who can write the job folder can
   write a file with a matching CRC. A machine that holds the same key refuses a file without the
   right HMAC (NOT_SIGNED): only a holder of the key can make a job it runs
   (:func:`read_job_key` reads one from a file).

Atomic: the body and trailer go to a temporary file in the same folder, are flushed and fsynced,
then a hard link gives the file its name in one step that fails when the name exists (and the
folder is fsynced), so the machine never sees a half-written job under a job's name and a job file
is never overwritten, not even one another writer puts there at the same moment (ids are never
reused). On a file system without hard links the name is first claimed with an exclusive create
(an empty file, which the machine would refuse as truncated) and then replaced by the job.
"""

from __future__ import annotations

import errno
import hashlib
import hmac
import json
import logging
import math
import os
import re
import tempfile
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wavestack.drivers.plc.jobs import MAX_JOB_ID, JobRefused, JobSummary

__all__ = ["JOB_FORMAT", "JOB_FORMAT_VERSION", "JobFile", "JobReceipt", "encode_job_file", "job_file_name",
           "read_job_key", "used_job_ids", "write_job_file"]

_log = logging.getLogger(__name__)

JOB_FORMAT = "wavestack-polishing-job"
JOB_FORMAT_VERSION = 1
_TRAILER = "wsjob-crc32"
_NAME = re.compile(r"^job-(\d{5})\.wsjob$")
_COLUMNS = ("x_mm", "y_mm", "dwell_s", "feed_mm_s")


def job_file_name(job_id: int) -> str:
    """The job file's name for ``job_id`` (1..65535).

    Examples
    --------
    >>> job_file_name(42)
    'job-00042.wsjob'
    """
    if isinstance(job_id, bool) or not isinstance(job_id, (int, np.integer)) or not 1 <= job_id <= MAX_JOB_ID:
        raise ValueError(f"job_id must be an integer 1..{MAX_JOB_ID}, got {job_id!r}")
    return f"job-{int(job_id):05d}.wsjob"


def used_job_ids(folder: Path) -> set[int]:
    """The job ids that have a job file in ``folder`` (an earlier session's jobs); empty for a missing folder."""
    try:
        names = os.listdir(folder)
    except FileNotFoundError:
        return set()
    return {int(m.group(1)) for m in map(_NAME.match, names) if m is not None}


def _column(name: str, values: ArrayLike) -> NDArray[np.float64]:
    array = np.array(values, dtype=np.float64)
    array.setflags(write=False)
    if array.ndim != 1 or array.size == 0:
        raise ValueError(f"JobFile.{name} must be a non-empty 1-D array, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"JobFile.{name} must be finite; index {int(np.flatnonzero(~np.isfinite(array))[0])} is not")
    return array


@dataclass(frozen=True)
class JobFile:
    """One polishing job: dwell points in the machine frame and what they were computed for.

    Attributes
    ----------
    job_id
        1..65535, never reused.
    x_mm, y_mm
        Point positions in the machine frame, mm, shape (K,) (see the module docstring for the frame).
    dwell_s
        Dwell at each point, s, shape (K,), >= 0.
    feed_mm_s
        Feed on the move into each point, mm/s, shape (K,), > 0.
    pixel_mm
        The grid's pixel size on the optic, mm (> 0).
    tif
        The tool influence function the host assumed, plain JSON (kind, fwhm_mm, peak_rate_nm_s, ...).
    aperture
        What the host measured on, plain JSON (pixel count, a hash of the mask, ...).
    created_utc
        ISO-8601 time the job was made (default: now).

    Raises
    ------
    ValueError
        A bad id, columns of different lengths or non-finite values, a negative dwell, a feed <= 0,
        or ``tif``/``aperture`` that are not plain JSON.
    """

    job_id: int
    x_mm: NDArray[np.float64] = field(repr=False)
    y_mm: NDArray[np.float64] = field(repr=False)
    dwell_s: NDArray[np.float64] = field(repr=False)
    feed_mm_s: NDArray[np.float64] = field(repr=False)
    pixel_mm: float
    tif: Mapping[str, Any]
    aperture: Mapping[str, Any]
    created_utc: str = field(default_factory=lambda: datetime.now(timezone.utc).isoformat(timespec="seconds"))

    def __post_init__(self) -> None:
        job_file_name(self.job_id)  # checks the id
        columns = {name: _column(name, getattr(self, name)) for name in _COLUMNS}
        lengths = {name: array.size for name, array in columns.items()}
        if len(set(lengths.values())) != 1:
            raise ValueError(f"JobFile columns must have one length, got {lengths}")
        for name, array in columns.items():
            object.__setattr__(self, name, array)
        if np.any(self.dwell_s < 0):
            raise ValueError(f"JobFile.dwell_s must be >= 0; index {int(np.argmin(self.dwell_s))} is {self.dwell_s.min()}")
        if np.any(self.feed_mm_s <= 0):
            raise ValueError(f"JobFile.feed_mm_s must be > 0; the smallest is {self.feed_mm_s.min()}")
        if not (math.isfinite(self.pixel_mm) and self.pixel_mm > 0):
            raise ValueError(f"JobFile.pixel_mm must be finite and > 0, got {self.pixel_mm!r}")
        for name in ("tif", "aperture"):
            try:
                json.dumps(dict(getattr(self, name)), allow_nan=False)
            except (TypeError, ValueError) as error:
                raise ValueError(f"JobFile.{name} must be plain JSON (finite numbers, strings, lists): {error}") \
                    from None

    @property
    def point_count(self) -> int:
        """Number of points K."""
        return int(self.dwell_s.size)

    @property
    def total_dwell_s(self) -> float:
        """Sum of the dwell, s."""
        return float(np.sum(self.dwell_s))

    def summary(self) -> JobSummary:
        """Counts and extremes, for :class:`~wavestack.drivers.plc.jobs.JobLimits`."""
        return JobSummary(job_id=int(self.job_id), point_count=self.point_count, total_dwell_s=self.total_dwell_s,
                          max_dwell_s=float(self.dwell_s.max()), min_dwell_s=float(self.dwell_s.min()),
                          max_feed_mm_s=float(self.feed_mm_s.max()), min_feed_mm_s=float(self.feed_mm_s.min()),
                          x_range_mm=(float(self.x_mm.min()), float(self.x_mm.max())),
                          y_range_mm=(float(self.y_mm.min()), float(self.y_mm.max())))


@dataclass(frozen=True)
class JobReceipt:
    """What :func:`write_job_file` wrote: announce these over Modbus.

    Attributes
    ----------
    path
        The job file.
    crc32
        CRC-32 of the file's body (also in its trailer).
    point_count, total_dwell_s
        As in the body.
    summary
        The job's counts and extremes, for the link's :class:`~wavestack.drivers.plc.jobs.JobLimits`.
    """

    path: Path
    crc32: int
    point_count: int
    total_dwell_s: float
    summary: JobSummary


def read_job_key(path: str | Path) -> bytes:
    """The job key in a key file: hexadecimal text of at least 16 bytes (32 hex digits), whitespace around.

    Make one with ``python3 -c "import secrets; print(secrets.token_hex(32))" > job.key``; the
    machine's controller holds the same key.

    Raises
    ------
    ValueError
        The file cannot be read, or does not hold such a key; the message names it.
    """
    try:
        text = Path(path).read_text(encoding="ascii").strip()
        key = bytes.fromhex(text)
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise ValueError(f"job key file {path}: expected hexadecimal text of at least 32 digits ({error})") from None
    if len(key) < 16:
        raise ValueError(f"job key file {path}: a key of {len(key)} bytes; expected at least 16 (32 hex digits)")
    return key


def encode_job_file(job: JobFile, key: bytes | None = None) -> tuple[bytes, int]:
    """The file's bytes (body, newline, trailer; the HMAC too with a ``key``) and the body's CRC-32 (pure)."""
    header = {
        "format": JOB_FORMAT, "version": JOB_FORMAT_VERSION, "job_id": int(job.job_id), "created_utc": job.created_utc,
        "units": {"position": "mm", "dwell": "s", "feed": "mm/s"},
        "frame": {"origin": "grid centre", "x": "right", "y": "up", "pixel_mm": float(job.pixel_mm),
                  "x_mm": "(col - (W - 1) / 2) * pixel_mm", "y_mm": "((H - 1) / 2 - row) * pixel_mm"},
        "tif": dict(job.tif), "aperture": dict(job.aperture),
        "point_count": job.point_count, "total_dwell_s": job.total_dwell_s, "columns": list(_COLUMNS),
    }
    lines = [f" {json.dumps(key)}: {json.dumps(value, allow_nan=False)}," for key, value in header.items()]
    rows = np.column_stack([job.x_mm, job.y_mm, job.dwell_s, job.feed_mm_s]).tolist()
    points = ",\n".join("  " + json.dumps(row, allow_nan=False) for row in rows)
    body = ("{\n" + "\n".join(lines) + '\n "points": [\n' + points + "\n ]\n}").encode("utf-8")
    crc = zlib.crc32(body) & 0xFFFFFFFF
    signature = "" if key is None else f" hmac-sha256 {hmac.new(key, body, hashlib.sha256).hexdigest()}"
    return body + f"\n{_TRAILER} {crc:08x} {len(body)}{signature}\n".encode("ascii"), crc


def write_job_file(folder: Path, job: JobFile, *, key: bytes | None = None) -> JobReceipt:
    """Write ``job`` into ``folder`` atomically; the receipt to announce.

    Parameters
    ----------
    folder
        The job folder (must exist: a network share on a real station, a local folder in simulation).
    job
        The job.
    key
        The job key (:func:`read_job_key`): the trailer then carries the body's HMAC-SHA256.

    Returns
    -------
    JobReceipt
        Path, CRC-32, point count, total dwell and the job's summary.

    Raises
    ------
    JobRefused
        A file for this job id exists already (ids are never reused).
    OSError
        The folder is missing or not writable; no file is left behind.

    Examples
    --------
    >>> import tempfile, numpy as np
    >>> job = JobFile(7, np.array([0.0, 1.0]), np.array([0.0, 0.0]), np.array([0.5, 1.5]), np.array([10.0, 10.0]),
    ...               0.1, {"kind": "gaussian"}, {"pixels": 100})
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     receipt = write_job_file(Path(folder), job)
    ...     (receipt.path.name, receipt.point_count, receipt.total_dwell_s)
    ('job-00007.wsjob', 2, 2.0)
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise OSError(f"job folder {folder} does not exist or is not a folder")
    path = folder / job_file_name(job.job_id)
    data, crc = encode_job_file(job, key)
    handle, temporary = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "wb") as stream:
            stream.write(data)
            stream.flush()
            os.fsync(stream.fileno())
        _name_without_overwrite(Path(temporary), path, job.job_id)
    finally:
        Path(temporary).unlink(missing_ok=True)
    _fsync_folder(folder)
    _log.info("job %d written to %s (%d points, %.3f s dwell, CRC-32 %08x)", job.job_id, path, job.point_count,
              job.total_dwell_s, crc)
    return JobReceipt(path=path, crc32=crc, point_count=job.point_count, total_dwell_s=job.total_dwell_s,
                      summary=job.summary())


def _name_without_overwrite(temporary: Path, path: Path, job_id: int) -> None:
    """Give the written file its job name in one step that never replaces an existing name (module notes)."""
    refused = JobRefused(str(path.parent), f"refusing to overwrite {path.name}: job id {job_id} was used before")
    try:
        os.link(temporary, path)  # fails with EEXIST whatever is there: a file, a link, a dangling symlink
        return
    except FileExistsError:
        raise refused from None
    except OSError as error:
        if error.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EMLINK, errno.ENOSYS):
            raise
    try:  # no hard links here: claim the name exclusively, then replace the empty claim with the job
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
    except FileExistsError:
        raise refused from None
    os.replace(temporary, path)


def _fsync_folder(folder: Path) -> None:
    """Make the rename durable (POSIX); a file system that cannot fsync a folder is left as it is."""
    try:
        descriptor = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(descriptor)
    except OSError:
        pass
    finally:
        os.close(descriptor)
