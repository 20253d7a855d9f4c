"""Read a station recording back, also one whose writer was killed (committed rows only).

``wavestack replay FILE.h5`` reads with :class:`RecordingReader`. The layout is described in
:mod:`wavestack.recording.format`, the commit protocol that makes the file crash-safe in
:mod:`wavestack.recording.writer`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from wavestack.drivers.frames import Frame
from wavestack.pipeline import InputError
from wavestack.recording.format import _FRAME_COLUMNS, FORMAT_NAME, FORMAT_VERSION, _ResultColumns


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
    n_sets, frames_per_set : int
    frame_shape : tuple[int, int]
    frame_dtype : numpy.dtype
    set_indices : ndarray, int64 (n_sets,)
        The station's set index of each recorded set (``read_set(i)`` is set ``set_indices[i]``).
    metadata_keys : tuple[str, ...]
    closed_cleanly : bool
        False if the writer has not closed the file (it was killed, or is still writing); the reader
        then opens it in SWMR mode and sees the rows committed when it opened.

    Raises
    ------
    InputError
        Missing file, not HDF5, not a wavestack recording, damaged, or a newer format version.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(f"{self.path}: no such file")
        if not h5py.is_hdf5(self.path):
            raise InputError(f"{self.path}: not an HDF5 file; expected a wavestack recording")
        self._file, self.closed_cleanly = _open_hdf5(self.path)
        try:
            self._load()
        except BaseException:
            self._file.close()
            raise

    def _load(self) -> None:
        root = self._file
        if root.attrs.get("format") != FORMAT_NAME:
            raise InputError(f"{self.path}: not a wavestack recording (expected root attribute "
                             f"format={FORMAT_NAME!r})")
        self.format_version = int(root.attrs.get("format_version", -1))
        if self.format_version > FORMAT_VERSION:
            raise InputError(f"{self.path}: recording format version {self.format_version} is newer than this "
                             f"wavestack reads (up to {FORMAT_VERSION}); upgrade wavestack to replay it")
        try:
            self.config_toml = str(root.attrs["config_toml"])
            self.software_version = str(root.attrs["software_version"])
            self.conventions = {k: _python_scalar(v) for k, v in root["conventions"].attrs.items()}
            committed = root["committed_counts"][:]
            sets = root["sets"]
            self._pixels = sets["pixels"]
            metadata = sets["metadata"] if "metadata" in sets else {}
            set_columns = [sets["set_index"], *(sets[n] for n in _FRAME_COLUMNS), *metadata.values()]
            self.n_sets = min(int(committed[0]), *(len(d) for d in (self._pixels, *set_columns)))
            self.set_indices = sets["set_index"][: self.n_sets]
            self._frame_columns = {n: sets[n][: self.n_sets] for n in _FRAME_COLUMNS}
            self._metadata = {k: d[: self.n_sets] for k, d in metadata.items()}
            self._masks = root["apertures/mask"]
            n_apertures = min(int(committed[1]), len(self._masks), len(root["apertures/from_set"]))
            self._aperture_from = root["apertures/from_set"][:n_apertures]
            self._results = _ResultColumns.open(root["results"], int(committed[2]))
        except (KeyError, TypeError, ValueError) as error:
            raise InputError(f"{self.path}: damaged wavestack recording ({error})") from error
        self.frames_per_set = int(self._pixels.shape[1])
        self.frame_shape = (int(self._pixels.shape[2]), int(self._pixels.shape[3]))
        self.frame_dtype = self._pixels.dtype
        self.metadata_keys = tuple(self._metadata)

    def read_set(self, i: int) -> tuple[Frame, ...]:
        """The ``i``-th recorded set (0 <= i < n_sets), metadata restored as floats (NaN omitted).

        Raises
        ------
        IndexError
            ``i`` out of range.
        """
        if not 0 <= i < self.n_sets:
            raise IndexError(f"{self.path}: set {i} out of range, the recording holds {self.n_sets} sets")
        pixels = self._pixels[i]
        ids, host, device = (self._frame_columns[n][i] for n in _FRAME_COLUMNS)
        frames = []
        for j in range(self.frames_per_set):
            metadata = {k: float(v[i, j]) for k, v in self._metadata.items() if not math.isnan(v[i, j])}
            frames.append(Frame(int(ids[j]), int(host[j]), int(device[j]), pixels[j], metadata))
        return tuple(frames)

    def iter_sets(self) -> Iterator[tuple[Frame, ...]]:
        """Every recorded set in order (see :meth:`read_set`)."""
        for i in range(self.n_sets):
            yield self.read_set(i)

    def aperture_for(self, set_index: int) -> NDArray[np.bool_] | None:
        """The latest aperture recorded from or before station set ``set_index`` (bool, frame_shape).

        ``None`` if no aperture applies yet.
        """
        position = int(np.searchsorted(self._aperture_from, set_index, side="right")) - 1
        return None if position < 0 else np.asarray(self._masks[position], dtype=np.bool_)

    def results(self) -> dict[str, NDArray[Any]]:
        """Result columns in recording order: (n_results, *shape) arrays; strings as object arrays of ``str``."""
        return self._results.read()

    @property
    def n_results(self) -> int:
        """Number of committed result rows."""
        return self._results.n_rows

    def close(self) -> None:
        """Close the file; idempotent."""
        self._file.close()

    def __enter__(self) -> RecordingReader:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


def _open_hdf5(path: Path) -> tuple[h5py.File, bool]:
    """Open read-only; a file still flagged "open for write" (killed SWMR writer) opens in SWMR mode."""
    try:
        return h5py.File(path, "r"), True
    except OSError as first:
        try:
            return h5py.File(path, "r", libver="latest", swmr=True), False
        except OSError:
            raise InputError(f"{path}: HDF5 file cannot be opened ({first}); a recording whose writer was killed "
                             "before it became crash-safe (before its first result) needs `h5clear -s` first"
                             ) from first


def _python_scalar(value: Any) -> Any:
    """An attribute value as a plain Python str, int or float."""
    if isinstance(value, bytes):
        return value.decode("utf-8")
    return value.item() if isinstance(value, np.generic) else value
