"""A loop's campaign record: every event, measurement and action as one checksummed HDF5 record, flushed as it goes.

Layout (``format_version`` 2; the format name is the loop's, e.g. ``wavestack-polish-campaign``)::

    /                   attrs: format, format_version, software_version, created_utc, config_toml,
                        header (JSON: the loop's own attributes), header_crc32; words as
                        fixed-length UTF-8 bytes
    /records/NNNNNN     one group per record, written once and never rewritten:
                        attrs kind, fields (JSON: numbers, words, lists of them), crc32;
                        datasets: the record's arrays (maps float32, gzip level 1 with shuffle,
                        one chunk per array, fletcher32; bytes as uint8)

Integrity is the station recording's (:mod:`wavestack.recording.format`): a CRC-32 per record
(:func:`record_crc32`) over its kind, its fields and each array's name, dtype, shape and bytes as
stored, checked by the reader on the values it reads back; HDF5's metadata checksums
(``libver="latest"``); ``header_crc32`` over the root attributes. Words are stored as fixed-length
bytes in the object headers, never as variable-length strings: those live in HDF5's global heap,
which carries no checksum and whose damage can make the library loop forever
(:mod:`wavestack.pipeline.formats`' guard notes it). The record's attributes are
written after its arrays, the CRC last, so a writer stopped half-way leaves a record without a CRC,
which the reader names as incomplete. Append-only: a record that supersedes an earlier one (a run
completed after it was handed off) is a new record with the same key, so a fault while writing
never damages what was already on disk. The file is created exclusively (``w-``: an existing file
is never overwritten) and flushed after every record; the reader opens it through
:func:`~wavestack.pipeline.formats.hdf5_open.open_hdf5_readonly` (never SWMR read mode, so a damaged or
truncated file is an error at once, never a wait) and returns every intact record with the
damaged ones named (:func:`read_campaign`).
"""

from __future__ import annotations

import json
import math
import time
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Final

import h5py
import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline import InputError
from wavestack.pipeline.formats import check_allocation
from wavestack.pipeline.formats.hdf5_open import open_hdf5_readonly

__all__ = ["CAMPAIGN_VERSION", "MAP_KIND", "CampaignEntry", "CampaignLog", "CampaignWriter", "read_campaign",
           "record_crc32"]

CAMPAIGN_VERSION: Final = 2
#: The kind of a record that holds one measured map (array ``map``, field ``units``; the first of a
#: campaign also ``aperture_mask``): what ``wavestack batch`` refits, whichever loop wrote it.
MAP_KIND: Final = "map"
_RECORDS: Final = "records"

#: A record's fields: JSON numbers, words and lists of them (NaN is written as null).
Fields = Mapping[str, Any]


def _json_value(value: Any) -> Any:
    if isinstance(value, (np.generic,)):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, (list, tuple)):
        return [_json_value(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): _json_value(v) for k, v in value.items()}
    return value


def _fields_text(fields: Fields) -> str:
    return json.dumps({str(k): _json_value(v) for k, v in fields.items()}, sort_keys=True, allow_nan=False)


def _stored(array: NDArray[Any] | bytes) -> NDArray[Any]:
    """An array as the record stores it: floating maps as float32, bytes as uint8, other arrays as they are."""
    if isinstance(array, (bytes, bytearray)):
        return np.frombuffer(bytes(array), dtype=np.uint8)
    values = np.asarray(array)
    return values.astype(np.float32) if values.dtype.kind == "f" else values


def record_crc32(kind: str, fields_text: str, arrays: Mapping[str, NDArray[Any]]) -> int:
    """CRC-32 of one record as stored: kind, fields' JSON, then each array (sorted by name): name, dtype, shape, bytes.

    Example
    -------
    >>> record_crc32("event", '{"phase": "measuring"}', {}) == record_crc32("event", '{"phase": "measuring"}', {})
    True
    """
    crc = zlib.crc32(kind.encode("utf-8") + b"\0" + fields_text.encode("utf-8"))
    for name in sorted(arrays):
        values = np.ascontiguousarray(arrays[name])
        head = f"{name}\0{values.dtype.str}\0{list(values.shape)}\0".encode("utf-8")
        crc = zlib.crc32(head + values.tobytes(), crc)
    return crc


def _word(text: str) -> np.bytes_:
    """A word as a fixed-length UTF-8 attribute (module notes)."""
    return np.bytes_(text.encode("utf-8"))


def _header_crc32(root: Mapping[str, Any]) -> int:
    keys = ("format", "format_version", "software_version", "created_utc", "config_toml", "header")
    return zlib.crc32(json.dumps({k: _text(root.get(k)) for k in keys}, sort_keys=True).encode("utf-8"))


def _text(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    return value.item() if isinstance(value, np.generic) else value


class CampaignWriter:
    """Writes one loop's campaign record (module notes).

    Parameters
    ----------
    path : Path
        A new file (checked beforehand by the caller: ``check_recording_path``); an existing one
        raises ``FileExistsError``.
    format_name : str
        The loop's format, e.g. ``"wavestack-polish-campaign"``.
    config_text : str
        The configuration the campaign ran with.
    header : mapping
        The loop's own attributes (numbers and words: grid, units, options).
    software_version : str

    Example
    -------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     writer = CampaignWriter(Path(folder) / "c.h5", "wavestack-demo", "", {"grid": [4, 4]})
    ...     writer.event("measuring", "start")
    ...     _ = writer.append("measurement", {"rms_nm": 3.0}, {"surface_nm": np.zeros((4, 4))})
    ...     writer.close({"final_phase": "target-met"})
    ...     [entry.kind for entry in read_campaign(Path(folder) / "c.h5", "wavestack-demo").records]
    ['event', 'measurement', 'end']
    """

    def __init__(self, path: Path, format_name: str, config_text: str, header: Fields, *,
                 software_version: str = "") -> None:
        self.path = Path(path)
        self._file: h5py.File | None = h5py.File(self.path, "w-", libver="latest", locking=False)
        root = self._file.attrs
        root["format"], root["format_version"] = _word(format_name), CAMPAIGN_VERSION
        root["software_version"] = _word(software_version)
        root["created_utc"] = _word(datetime.now(timezone.utc).isoformat())
        root["config_toml"] = _word(config_text)
        root["header"] = _word(_fields_text(header))
        root["header_crc32"] = _header_crc32({k: root[k] for k in root})
        self._file.create_group(_RECORDS, track_order=True)
        self._count = 0
        self._file.flush()

    @property
    def records(self) -> int:
        """Records written so far."""
        return self._count

    def append(self, kind: str, fields: Fields, arrays: Mapping[str, NDArray[Any] | bytes] | None = None) -> int:
        """Write one record and flush; returns its index.

        Raises
        ------
        ValueError
            The writer is closed, or a field is not JSON (a number, a word, a list or mapping of them).
        """
        if self._file is None:
            raise ValueError(f"{self.path}: the campaign record is closed")
        text = _fields_text(fields)
        stored = {name: _stored(values) for name, values in (arrays or {}).items()}
        group = self._file[_RECORDS].create_group(f"{self._count:06d}")
        for name, values in stored.items():
            extra: dict[str, Any] = {"compression": "gzip", "compression_opts": 1, "shuffle": True} \
                if values.ndim >= 2 else {}
            group.create_dataset(name, data=values, fletcher32=True, chunks=values.shape if values.size else None,
                                 **extra)
        group.attrs["kind"] = _word(kind)
        group.attrs["fields"] = _word(text)
        group.attrs["crc32"] = np.uint32(record_crc32(kind, text, stored))
        self._file.flush()
        self._count += 1
        return self._count - 1

    def event(self, phase: str, reason: str) -> int:
        """One transition of the loop: the phase entered and why."""
        return self.append("event", {"unix_s": time.time(), "phase": phase, "reason": reason})

    def append_map(self, values: NDArray[np.floating], *, units: str, exposure_unix_s: float,
                   mask: NDArray[np.bool_] | None = None, fields: Fields | None = None) -> int:
        """One measured map (a :data:`MAP_KIND` record; NaN outside the aperture) with its ``fields``."""
        arrays: dict[str, NDArray[Any]] = {"map": np.asarray(values)}
        if mask is not None:
            arrays["aperture_mask"] = np.asarray(mask, dtype=bool)
        return self.append(MAP_KIND, {**(fields or {}), "units": units, "exposure_unix_s": exposure_unix_s}, arrays)

    def close(self, ending: Fields) -> None:
        """Write the ``end`` record (how the campaign ended) and close the file; idempotent."""
        if self._file is None:
            return
        try:
            self.append("end", ending)
        finally:
            self._file.close()
            self._file = None


@dataclass(frozen=True, eq=False)
class CampaignEntry:
    """One intact record as read back.

    Attributes
    ----------
    index : int
    kind : str
    fields : mapping
        As written (JSON: NaN came back as None).
    arrays : mapping of name -> ndarray
    """

    index: int
    kind: str
    fields: Fields
    arrays: Mapping[str, NDArray[Any]]


@dataclass(frozen=True, eq=False)
class CampaignLog:
    """A campaign record as read: the header, every intact record in order, and what was damaged.

    Attributes
    ----------
    path : Path
    format_name : str
    header : mapping
        The loop's own attributes.
    config_text : str
    records : tuple of CampaignEntry
    damage : tuple of str
        One line per damaged or incomplete record (and a damaged header).
    closed_cleanly : bool
        False when the writer never closed the file.
    """

    path: Path
    format_name: str
    header: Fields
    config_text: str
    records: tuple[CampaignEntry, ...]
    damage: tuple[str, ...]
    closed_cleanly: bool

    def of_kind(self, kind: str) -> tuple[CampaignEntry, ...]:
        """The intact records of one kind, in order."""
        return tuple(entry for entry in self.records if entry.kind == kind)


def read_campaign(path: Path, format_name: str | None = None) -> CampaignLog:
    """Read a campaign record: every intact record, the damaged ones named (module notes).

    ``format_name`` None accepts any loop's campaign record. A file cut short (a partial copy)
    keeps only what HDF5 can still reach: the records' index is rewritten as the file grows, so
    a cut through it leaves no record readable; the damage says so.

    Raises
    ------
    InputError
        Not a file, not HDF5, a damaged superblock or root, another format, a newer version, or a
        record array larger than the memory budget (checked before it is read); the message names the file.
    """
    path = Path(path)
    opened = open_hdf5_readonly(path)
    with opened.file as file:
        try:
            root = file.attrs
            found = _text(root.get("format"))
            version = _text(root.get("format_version"))
        except (KeyError, ValueError, TypeError, OSError, RuntimeError) as error:
            raise InputError(f"{path}: damaged campaign record: its root is unreadable ({error})") from None
        if format_name is not None and found != format_name:
            raise InputError(f"{path}: not a {format_name} record (format {found!r})")
        if version != CAMPAIGN_VERSION:
            raise InputError(f"{path}: {found} record version {version!r}; this wavestack reads version "
                             f"{CAMPAIGN_VERSION}")
        damage: list[str] = []
        if opened.truncated:
            damage.append(f"file truncated: {opened.file_bytes} bytes of the {opened.expected_bytes} its superblock "
                          "records")
        header, config_text = _read_header(root, damage)
        records = []
        try:
            group = file[_RECORDS]
            names = sorted(group)
        except (KeyError, ValueError, TypeError, OSError, RuntimeError) as error:
            damage.append(f"the records' index is unreadable ({error}): no record can be reached")
            names = []
        for name in names:
            try:
                entry, why = _read_entry(group[name], name, path)
            except (KeyError, ValueError, TypeError, OSError, RuntimeError) as error:
                entry, why = None, f"unreadable ({error})"
            if entry is None:
                damage.append(f"record {name}: {why}")
            else:
                records.append(entry)
        return CampaignLog(path, str(found), header, config_text, tuple(records), tuple(damage),
                           opened.closed_cleanly)


def _read_header(root: Mapping[str, Any], damage: list[str]) -> tuple[dict[str, Any], str]:
    """The loop's header and the configuration text, checked against ``header_crc32`` (damage noted)."""
    try:
        header = json.loads(_text(root["header"]))
        if int(_text(root["header_crc32"])) != _header_crc32({k: root[k] for k in root}):
            damage.append("header: CRC-32 mismatch (the configuration or the header changed on disk)")
        return header, str(_text(root.get("config_toml")) or "")
    except (KeyError, ValueError, TypeError, OSError, RuntimeError) as error:
        damage.append(f"header unreadable ({error})")
        return {}, ""


def _read_entry(node: Any, name: str, path: Path) -> tuple[CampaignEntry | None, str]:
    """One record checked against its CRC-32, or None and why not."""
    if not isinstance(node, h5py.Group):
        return None, "not a record group"
    if "crc32" not in node.attrs:
        return None, "incomplete (the writer stopped while writing it)"
    kind, text = str(_text(node.attrs["kind"])), str(_text(node.attrs["fields"]))
    arrays = {}
    for key in node:
        dataset = node[key]
        if not isinstance(dataset, h5py.Dataset):
            return None, f"{key}: not a dataset"
        check_allocation(path, f"record {name} {key}", dataset.shape, dataset.dtype.itemsize)  # before reading
        arrays[key] = np.asarray(dataset[()])
    if int(node.attrs["crc32"]) != record_crc32(kind, text, arrays):
        return None, "CRC-32 mismatch (changed on disk)"
    return CampaignEntry(int(name), kind, json.loads(text), arrays), ""
