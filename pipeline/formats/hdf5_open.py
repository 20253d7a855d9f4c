"""Open an HDF5 file read-only without ever waiting: also one that is truncated or whose writer was killed.

Station recordings, campaign records and any other HDF5 file a reader must not hang on open
through :func:`open_hdf5_readonly`.

Why not SWMR read mode
----------------------
A file whose SWMR writer was killed keeps "open for write" flags in its superblock, and HDF5
refuses to open it read-only except in SWMR read mode. But SWMR read mode also skips HDF5's
end-of-file check and, on a metadata checksum mismatch, re-reads the block up to 100 times with a
growing sleep between attempts (``H5Pset_metadata_read_attempts``: the SWMR default is 100),
because a live writer may be half-way through updating it. On a truncated file, or one whose
metadata is damaged, every read of a missing or damaged block then waits for minutes at ~1 % CPU:
this was the hang of ``wavestack replay`` on recordings truncated to 0.1-10 % (issue 13).

So this module never uses SWMR read mode. It reads the superblock itself (versions 2 and 3, the
ones ``libver="latest"`` writes), checks its checksum, and when the file is flagged "open for
write" or is shorter than the superblock says, opens it through a read-only view
(:class:`_SuperblockView`, h5py's ``fileobj`` driver) that presents the superblock with its flags
cleared (checksum recomputed) and the missing tail as zeros. HDF5 then reads in its ordinary mode:
one attempt per block, so a missing or damaged block is an immediate error, never a wait. The
file on disk is never written.

A killed SWMR writer's file is consistent on disk (SWMR orders its metadata flushes), so reading
it in ordinary mode sees what SWMR read mode would.
"""

from __future__ import annotations

import io
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import h5py

from .errors import InputError

HDF5_SIGNATURE: Final = b"\x89HDF\r\n\x1a\n"
_FLAGS_OFFSET: Final = 11  # signature (8), version, size of offsets, size of lengths, then the status flags


@dataclass(frozen=True)
class OpenedHDF5:
    """An HDF5 file opened read-only, and what its superblock said about it.

    Attributes
    ----------
    file : h5py.File
    closed_cleanly : bool
        False when the writer never closed the file (killed, or still writing).
    file_bytes : int
        Size of the file on disk.
    expected_bytes : int or None
        End of file recorded in the superblock (None for superblock versions 0 and 1).
    """

    file: h5py.File
    closed_cleanly: bool
    file_bytes: int
    expected_bytes: int | None

    @property
    def truncated(self) -> bool:
        """True when a cleanly closed file is shorter than its superblock says (a cut copy)."""
        return self.closed_cleanly and self.expected_bytes is not None and self.file_bytes < self.expected_bytes


def open_hdf5_readonly(path: Path) -> OpenedHDF5:
    """Open ``path`` read-only without SWMR read mode (see the module docstring).

    Raises
    ------
    InputError
        Not a file, empty, not HDF5, a damaged superblock, or HDF5 cannot open it; the message
        names the file.
    """
    if path.is_dir():
        raise InputError(f"{path}: is a directory; expected a wavestack recording (an HDF5 file)")
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    size = path.stat().st_size
    if size == 0:
        raise InputError(f"{path}: empty file; expected a wavestack recording (an HDF5 file)")
    with path.open("rb") as stream:
        head = stream.read(48)
    if not head.startswith(HDF5_SIGNATURE):
        if not h5py.is_hdf5(path):  # a user block would put the signature at 512, 1024, ...
            raise InputError(f"{path}: not an HDF5 file; expected a wavestack recording")
        return OpenedHDF5(_h5py_open(path, path), True, size, None)
    superblock = _parse_superblock(path, head)
    if superblock is None:  # versions 0 and 1: no status flags, HDF5 checks the rest itself
        return OpenedHDF5(_h5py_open(path, path), True, size, None)
    flags, eof = superblock
    if flags == 0 and size >= eof:
        return OpenedHDF5(_h5py_open(path, path), True, size, eof)
    cleared = head[:_FLAGS_OFFSET] + b"\x00" + head[_FLAGS_OFFSET + 1: 44]
    patched = cleared + struct.pack("<I", lookup3(cleared))
    view = _SuperblockView(path, patched, max(size, eof))
    try:
        return OpenedHDF5(_h5py_open(view, path), flags == 0, size, eof)
    except BaseException:
        view.close()
        raise


def _parse_superblock(path: Path, head: bytes) -> tuple[int, int] | None:
    """(status flags, end-of-file address) of a version 2/3 superblock; None for versions 0/1."""
    if len(head) < 9:
        raise InputError(f"{path}: truncated HDF5 superblock ({len(head)} bytes); expected a wavestack recording")
    version = head[8]
    if version in (0, 1):
        return None
    if version not in (2, 3) or len(head) < 48 or head[9] != 8:
        raise InputError(f"{path}: damaged HDF5 superblock (version {version}, {len(head)} bytes, offsets of "
                         f"{head[9] if len(head) > 9 else '?'} bytes); expected version 2 or 3 with 8-byte offsets")
    stored = struct.unpack("<I", head[44:48])[0]
    if lookup3(head[:44]) != stored:
        raise InputError(f"{path}: damaged HDF5 superblock (checksum mismatch); the file cannot be read")
    base, _extension, eof, _root = struct.unpack("<4Q", head[12:44])
    return head[_FLAGS_OFFSET], base + eof


def _h5py_open(source: Path | _SuperblockView, path: Path) -> h5py.File:
    try:
        return h5py.File(source, "r", locking=False) if isinstance(source, Path) else h5py.File(source, "r")
    except (OSError, ValueError) as error:
        raise InputError(f"{path}: HDF5 cannot open it ({error}); the file is damaged") from error


class _SuperblockView(io.RawIOBase):
    """A read-only view of a file: the first bytes replaced by ``superblock``, padded with zeros to ``size``."""

    def __init__(self, path: Path, superblock: bytes, size: int) -> None:
        super().__init__()
        self._stream = path.open("rb")
        self._superblock = superblock
        self._size = size
        self._position = 0

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        base = {io.SEEK_SET: 0, io.SEEK_CUR: self._position, io.SEEK_END: self._size}[whence]
        self._position = max(0, base + offset)
        return self._position

    def tell(self) -> int:
        return self._position

    def readinto(self, buffer: bytearray | memoryview) -> int:  # type: ignore[override]
        view = memoryview(buffer).cast("B")
        wanted = max(0, min(len(view), self._size - self._position))
        self._stream.seek(self._position)
        got = self._stream.readinto(view[:wanted]) or 0
        view[got:wanted] = bytes(wanted - got)  # beyond the real end: zeros, which fail every checksum
        head = self._superblock
        if self._position < len(head):
            stop = min(len(head), self._position + wanted)
            view[: stop - self._position] = head[self._position: stop]
        self._position += wanted
        return wanted

    def close(self) -> None:
        self._stream.close()
        super().close()


def lookup3(data: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 ``hashlittle``, the checksum of HDF5 metadata (``H5_checksum_lookup3``).

    Examples
    --------
    >>> hex(lookup3(b""))  # 0xdeadbeef: no block hashed
    '0xdeadbeef'
    """
    mask = 0xFFFFFFFF
    a = b = c = (0xDEADBEEF + len(data) + initval) & mask

    def rot(x: int, k: int) -> int:
        return ((x << k) | (x >> (32 - k))) & mask

    rest = data
    while len(rest) > 12:
        a = (a + int.from_bytes(rest[0:4], "little")) & mask
        b = (b + int.from_bytes(rest[4:8], "little")) & mask
        c = (c + int.from_bytes(rest[8:12], "little")) & mask
        for x, z, y, k in ((0, 2, 1, 4), (1, 0, 2, 6), (2, 1, 0, 8), (0, 2, 1, 16), (1, 0, 2, 19), (2, 1, 0, 4)):
            v = [a, b, c]  # mix: x -= z; x ^= rot(z, k); z += y
            v[x] = ((v[x] - v[z]) & mask) ^ rot(v[z], k)
            v[z] = (v[z] + v[y]) & mask
            a, b, c = v
        rest = rest[12:]
    if not rest:
        return c
    tail = rest + bytes(12 - len(rest))
    a = (a + int.from_bytes(tail[0:4], "little")) & mask
    b = (b + int.from_bytes(tail[4:8], "little")) & mask
    c = (c + int.from_bytes(tail[8:12], "little")) & mask
    for x, y, k in ((2, 1, 14), (0, 2, 11), (1, 0, 25), (2, 1, 16), (0, 2, 4), (1, 0, 14), (2, 1, 24)):
        v = [a, b, c]  # final: x ^= y; x -= rot(y, k)
        v[x] = ((v[x] ^ v[y]) - rot(v[y], k)) & mask
        a, b, c = v
    return c
