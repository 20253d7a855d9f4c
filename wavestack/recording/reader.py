"""Read a station recording back: what is intact, and a report of what is not.

``wavestack replay FILE.h5`` reads with :class:`RecordingReader`. The layout and its checksums are
described in :mod:`wavestack.recording.format`, the commit protocol in
:mod:`wavestack.recording.writer`, why no read can wait in :mod:`wavestack.pipeline.formats.hdf5_open`.

A malformed file (not HDF5, not a recording, a missing or mis-shaped dataset, a newer version, a
damaged header, rows or sets it declares but does not hold, or that exceed the memory budget)
raises :class:`~wavestack.pipeline.InputError` naming the file and what was expected, before
anything of that size is allocated. A damaged part of a well-formed recording (a truncated tail, a chunk failing its
checksum, a row failing its CRC-32) does not: the reader keeps what is intact and lists the rest in
:attr:`RecordingReader.damage`; reading a damaged set raises :class:`RecordingDamaged`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from wavestack.drivers.frames import Frame
from wavestack.pipeline import InputError
from wavestack.pipeline.formats import check_allocation
from wavestack.recording.format import (
    _FRAME_COLUMNS,
    FORMAT_NAME,
    FORMAT_VERSION,
    READABLE_VERSIONS,
    _chunk_damage,
    _ResultColumns,
    header_crc32,
    layout_crc32,
    read_rows,
    set_crc32,
)
from wavestack.pipeline.formats.hdf5_open import open_hdf5_readonly


class RecordingDamaged(InputError):
    """A set or an aperture of a recording that cannot be read intact (the message says which and why)."""


@dataclass(frozen=True)
class Damage:
    """Rows ``first`` .. ``last`` (positions in the recording) of ``part`` that could not be read intact."""

    part: str
    first: int
    last: int
    reason: str

    def __str__(self) -> str:
        if self.part == "file":
            return f"file {self.reason}"
        rows = f"{self.first}" if self.first == self.last else f"{self.first}-{self.last}"
        return f"{self.part} {rows}: {self.reason}"


class RecordingReader:
    """Read a station recording back (also one whose writer was killed: committed rows only).

    Parameters
    ----------
    path
        A file written by :class:`RecordingWriter`.

    Attributes
    ----------
    config_toml, software_version : str
    conventions : dict[str, str | int | float]
    format_version : int
    n_sets, frames_per_set : int
        ``n_sets`` counts the committed sets, intact or not.
    frame_shape : tuple[int, int]
    frame_dtype : numpy.dtype
    set_indices : ndarray, int64 (n_sets,)
        The station's set index of each recorded set (-1 where it could not be read).
    metadata_keys : tuple[str, ...]
    closed_cleanly : bool
        False if the writer has not closed the file (it was killed, or is still writing).
    notes : tuple[str, ...]
        What a user should know that is not damage (a killed writer, a recording without checksums).

    Raises
    ------
    InputError
        Missing file, a directory, empty, not HDF5, not a wavestack recording, malformed, a damaged
        header or superblock, or a newer format version; the message names the file.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        opened = open_hdf5_readonly(self.path)
        self._file, self.closed_cleanly, self._file_bytes = opened.file, opened.closed_cleanly, opened.file_bytes
        self._damage: list[Damage] = []
        if opened.truncated:
            self._damage.append(Damage("file", 0, 0, f"truncated: {opened.file_bytes} bytes of the "
                                                     f"{opened.expected_bytes} its superblock records"))
        try:
            self._load()
        except InputError:
            self._file.close()
            raise
        except (KeyError, TypeError, ValueError, OSError, RuntimeError, IndexError, AttributeError) as error:
            self._file.close()
            cut = f"file truncated ({self._damage[0].reason.split(': ', 1)[1]}), " if opened.truncated else ""
            raise InputError(f"{self.path}: damaged or malformed wavestack recording ({cut}{error})") from error
        except BaseException:
            self._file.close()
            raise

    # -- loading --------------------------------------------------------------------------------
    def _malformed(self, what: str) -> InputError:
        return InputError(f"{self.path}: malformed wavestack recording: expected {what}")

    def _dataset(self, name: str, kinds: str, ndim: int) -> h5py.Dataset:
        node = self._file.get(name)
        if not isinstance(node, h5py.Dataset) or node.dtype.kind not in kinds or node.ndim != ndim:
            found = "nothing" if node is None else (f"{node.dtype} {node.shape}" if isinstance(node, h5py.Dataset)
                                                    else type(node).__name__)
            raise self._malformed(f"dataset /{name} of {ndim} dimension(s) and kind {kinds!r}, found {found}")
        return node

    def _load(self) -> None:
        root = self._file
        if _text(root.attrs.get("format")) != FORMAT_NAME:
            raise InputError(f"{self.path}: not a wavestack recording (expected root attribute "
                             f"format={FORMAT_NAME!r})")
        version = root.attrs.get("format_version")
        if not isinstance(version, (int, np.integer)) or version < 1:
            raise self._malformed(f"an integer root attribute format_version >= 1, found {version!r}")
        self.format_version = int(version)
        if self.format_version > FORMAT_VERSION:
            raise InputError(f"{self.path}: recording format version {self.format_version} is newer than this "
                             f"wavestack reads (up to {FORMAT_VERSION}); upgrade wavestack to replay it")
        if self.format_version not in READABLE_VERSIONS:
            raise self._malformed(f"format_version in {READABLE_VERSIONS}, found {self.format_version}")
        self._load_header()
        counts = self._committed_counts()
        self._load_sets(counts)
        self._load_apertures()
        self._load_results(counts)
        notes = []
        if not self.closed_cleanly:
            notes.append(f"the writer did not close this recording (killed, or still writing): {self.n_sets} "
                         "committed sets read; anything after the last commit is not trusted")
        if self.format_version < 2:
            notes.append(f"format version {self.format_version} has no checksums: a truncated tail is detected, "
                         "changed bytes are not")
        self.notes = tuple(notes)

    def _load_header(self) -> None:
        root = self._file
        for name in ("config_toml", "software_version"):
            if _text(root.attrs.get(name)) is None:
                raise self._malformed(f"a string root attribute {name!r}")
        self.config_toml = _text(root.attrs["config_toml"]) or ""
        self.software_version = _text(root.attrs["software_version"]) or ""
        group = root.get("conventions")
        if not isinstance(group, h5py.Group):
            raise self._malformed("a group /conventions")
        self.conventions = {k: _python_scalar(v) for k, v in group.attrs.items()}
        if self.format_version >= 2 and root.attrs.get("header_crc32") != header_crc32(root.attrs, group.attrs):
            raise InputError(f"{self.path}: damaged wavestack recording: the configuration or conventions fail "
                             "their CRC-32 (header_crc32); the recording cannot be replayed faithfully")

    def _committed_counts(self) -> NDArray[np.int64] | None:
        counts, ok, why = read_rows(self._dataset("committed_counts", "iu", 1), 3, self._file_bytes)
        if len(ok) != 3:
            raise self._malformed(f"3 committed counts, found {len(ok)}")
        if not ok.all():
            self._damage.append(Damage("committed counts", 0, 2, f"{why}; trusting the dataset lengths"))
            return None
        return counts

    def _load_sets(self, committed: NDArray[np.int64] | None) -> None:
        pixels = self._dataset("sets/pixels", "uif", 4)
        self._pixels = pixels
        self.frames_per_set = int(pixels.shape[1])
        self.frame_shape = (int(pixels.shape[2]), int(pixels.shape[3]))
        self.frame_dtype = pixels.dtype
        check_allocation(self.path, "one recorded set", tuple(pixels.shape[1:]), pixels.dtype.itemsize)
        set_index = self._dataset("sets/set_index", "iu", 1)
        columns = {n: self._dataset(f"sets/{n}", "iu", 2) for n in _FRAME_COLUMNS}
        metadata = self._file.get("sets/metadata", {})
        metadata = {k: self._dataset(f"sets/metadata/{k}", "f", 2) for k in metadata}
        for name, d in [*columns.items(), *metadata.items()]:
            if d.shape[1] != self.frames_per_set:
                raise self._malformed(f"/sets/{name} of {self.frames_per_set} values per set, found {d.shape}")
        crc = self._dataset("integrity/set_crc32", "u", 1) if self.format_version >= 2 else None
        lengths = [len(d) for d in (pixels, set_index, *columns.values(), *metadata.values(), *([crc] if crc else []))]
        self.n_sets = min([*lengths, *([int(committed[0])] if committed is not None else [])])
        self.set_indices, ok, why = read_rows(set_index, self.n_sets, self._file_bytes)
        self._note_rows("sets", ok, f"set_index {why}")
        self._set_ok = ok
        self._frame_columns = {n: self._checked_rows("sets", d, n) for n, d in columns.items()}
        self._metadata = {k: self._checked_rows("sets", d, f"metadata {k!r}") for k, d in metadata.items()}
        self._set_crc = None if crc is None else self._checked_rows("sets", crc, "set_crc32")
        self.set_indices = np.where(self._set_ok, self.set_indices, -1).astype(np.int64)
        self.metadata_keys = tuple(self._metadata)

    def _checked_rows(self, part: str, dataset: h5py.Dataset, label: str) -> NDArray[Any]:
        values, ok, why = read_rows(dataset, self.n_sets, self._file_bytes)
        self._note_rows(part, ok, f"{label} {why}")
        self._set_ok &= ok
        return values

    def _note_rows(self, part: str, ok: NDArray[np.bool_], reason: str) -> None:
        for first, last in _runs(~ok):
            self._damage.append(Damage(part, first, last, reason))

    def _load_apertures(self) -> None:
        self._masks = self._dataset("apertures/mask", "b", 3)
        if tuple(self._masks.shape[1:]) != self.frame_shape:
            raise self._malformed(f"/apertures/mask of frame shape {self.frame_shape}, found {self._masks.shape}")
        from_set = self._dataset("apertures/from_set", "iu", 1)
        n = min(len(self._masks), len(from_set))
        self._aperture_from, self._aperture_ok, why = read_rows(from_set, n, self._file_bytes)
        self._note_rows("apertures", self._aperture_ok, f"from_set {why}")
        for position in np.flatnonzero(self._aperture_ok).tolist():  # a handful of masks: check each now
            why = _chunk_damage(self._masks, position, self._file_bytes)
            if not why:
                try:
                    self._masks[position]
                except (OSError, RuntimeError) as error:
                    why = f"mask is unreadable ({error})"
            if why:
                self._aperture_ok[position] = False
                self._damage.append(Damage("apertures", position, position, why))

    def _load_results(self, committed: NDArray[np.int64] | None) -> None:
        group = self._file.get("results")
        if not isinstance(group, h5py.Group):
            raise self._malformed("a group /results")
        crc = self._dataset("integrity/result_crc32", "u", 1) if self.format_version >= 2 else None
        limits = [*([int(committed[2])] if committed is not None else []), *([len(crc)] if crc is not None else [])]
        table = _ResultColumns.open(group, min(limits, default=2**62))
        stored_layout = self._file["integrity"].attrs.get("layout_crc32") if crc is not None else None
        if stored_layout is not None and stored_layout != layout_crc32(table.columns, self.metadata_keys):
            raise InputError(f"{self.path}: damaged wavestack recording: the result column names or metadata keys "
                             "fail their CRC-32 (layout_crc32)")
        read = table.read(self._file_bytes)
        ok = read.ok.copy()
        self._note_rows("results", ok, read.reason)
        if crc is not None:
            stored, crc_ok, why = read_rows(crc, table.n_rows, self._file_bytes)
            self._note_rows("results", crc_ok | ~ok, f"result_crc32 {why}")  # rows not already reported
            ok &= crc_ok
            matches = np.array([not ok[r] or read.row_crc32(r) == int(stored[r]) for r in range(table.n_rows)], bool)
            self._note_rows("results", matches, "fail their CRC-32 (changed or zeroed bytes)")
            ok &= matches
        self._results = {key: values[ok] for key, values in read.columns.items()}
        self.n_results = int(ok.sum())

    # -- reading --------------------------------------------------------------------------------
    @property
    def damage(self) -> tuple[Damage, ...]:
        """Every part found damaged so far (at opening, and by :meth:`read_set` and :meth:`aperture_for`)."""
        merged: list[Damage] = []
        for d in self._damage:  # runs of rows damaged for the same reason, e.g. a truncated tail, as one
            last = merged[-1] if merged else None
            if last and (last.part, last.reason) == (d.part, d.reason) and last.last + 1 == d.first:
                merged[-1] = Damage(d.part, last.first, d.last, d.reason)
            else:
                merged.append(d)
        return tuple(merged)

    def read_set(self, i: int) -> tuple[Frame, ...]:
        """The ``i``-th recorded set (0 <= i < n_sets), metadata restored as floats (NaN omitted).

        Raises
        ------
        IndexError
            ``i`` out of range.
        RecordingDamaged
            The set cannot be read intact (it is then also listed in :attr:`damage`).
        """
        if not 0 <= i < self.n_sets:
            raise IndexError(f"{self.path}: set {i} out of range, the recording holds {self.n_sets} sets")
        if not self._set_ok[i]:
            raise RecordingDamaged(f"{self.path}: recorded set {i} is damaged (see the damage report)")
        pixels = self._read_pixels(i)
        ids, host, device = (self._frame_columns[n][i] for n in _FRAME_COLUMNS)
        if self._set_crc is not None:
            found = set_crc32(pixels, int(self.set_indices[i]), [ids, host, device],
                              [m[i] for m in self._metadata.values()])
            if found != int(self._set_crc[i]):
                raise self._set_damaged(i, "fails its CRC-32 (changed or zeroed bytes)")
        frames = []
        for j in range(self.frames_per_set):
            metadata = {k: float(v[i, j]) for k, v in self._metadata.items() if not math.isnan(v[i, j])}
            frames.append(Frame(int(ids[j]), int(host[j]), int(device[j]), pixels[j], metadata))
        return tuple(frames)

    def _read_pixels(self, i: int) -> NDArray[Any]:
        why = _chunk_damage(self._pixels, i, self._file_bytes)
        if not why:
            try:
                return np.asarray(self._pixels[i])
            except (OSError, RuntimeError) as error:
                why = f"fails its checksum ({error})" if "filter" in str(error) else f"is unreadable ({error})"
        raise self._set_damaged(i, f"pixel data {why}")

    def _set_damaged(self, i: int, reason: str) -> RecordingDamaged:
        """Mark set ``i`` damaged; the error to raise."""
        self._set_ok[i] = False
        self._damage.append(Damage("sets", i, i, reason))
        return RecordingDamaged(f"{self.path}: recorded set {i} (station set {int(self.set_indices[i])}): {reason}")

    def iter_sets(self) -> Iterator[tuple[Frame, ...]]:
        """Every recorded set in order (see :meth:`read_set`; a damaged set raises)."""
        for i in range(self.n_sets):
            yield self.read_set(i)

    @property
    def aperture_sets(self) -> NDArray[np.int64]:
        """The station set from which each recorded aperture applies (in recording order)."""
        return self._aperture_from.astype(np.int64)

    def aperture_for(self, set_index: int) -> NDArray[np.bool_] | None:
        """The latest aperture recorded from or before station set ``set_index`` (bool, frame_shape).

        ``None`` if no aperture applies yet.

        Raises
        ------
        RecordingDamaged
            That aperture cannot be read intact.
        """
        position = int(np.searchsorted(self._aperture_from, set_index, side="right")) - 1
        if position < 0:
            return None
        if self._aperture_ok[position]:
            try:
                return np.asarray(self._masks[position], dtype=np.bool_)
            except (OSError, RuntimeError) as error:  # read intact at opening: only if the file changed since
                raise RecordingDamaged(f"{self.path}: aperture {position} is unreadable ({error})") from error
        raise RecordingDamaged(f"{self.path}: aperture {position} is damaged (see the damage report)")

    def results(self) -> dict[str, NDArray[Any]]:
        """The intact result rows in recording order: (n_results, *shape) arrays; strings as object arrays."""
        return {key: values.copy() for key, values in self._results.items()}

    def close(self) -> None:
        """Close the file; idempotent."""
        self._file.close()

    def __enter__(self) -> RecordingReader:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


def _runs(bad: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """(first, last) of each run of True values."""
    runs: list[tuple[int, int]] = []
    for i in np.flatnonzero(bad).tolist():
        if runs and runs[-1][1] == i - 1:
            runs[-1] = (runs[-1][0], i)
        else:
            runs.append((i, i))
    return runs


def _text(value: Any) -> str | None:
    """A string attribute as str (None if it is not a string)."""
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    return value if isinstance(value, str) else None


def _python_scalar(value: Any) -> Any:
    """An attribute value as a plain Python str, int or float."""
    if isinstance(value, bytes):
        return value.decode("utf-8")
    return value.item() if isinstance(value, np.generic) else value
