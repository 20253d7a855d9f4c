"""Files a hostile but legitimate user gives the command line, written by the tests that use them.

Each builder writes one file into a folder and returns its path. The files are small (a few
kilobytes) even where they declare huge arrays: the point is that the readers believe nothing a
header says before checking it against the file and the memory budget.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import h5py
import numpy as np

_METROPRO_HEADER = 834


def metropro_dat(path: Path, *, wavelength_m: float = 632.8e-9, shape: tuple[int, int] = (32, 32),
                 counts: np.ndarray | None = None) -> Path:
    """A MetroPro format-1 ``.dat`` file with a phase array and no intensity (layout as the reader's)."""
    rows, cols = shape
    header = bytearray(_METROPRO_HEADER)
    struct.pack_into(">IHI", header, 0, 0x881B036F, 1, _METROPRO_HEADER)
    struct.pack_into(">HHI", header, 68, cols, rows, 4 * rows * cols)  # phase width, height, bytes
    struct.pack_into(">ff", header, 164, 0.5, wavelength_m)  # intf_scale_factor, wavelength_in
    struct.pack_into(">f", header, 176, 1.0)  # obliquity_factor
    struct.pack_into(">h", header, 218, 0)  # phase_res 0: R = 4096
    if counts is None:
        r, c = np.indices(shape)
        counts = (40 * (r - rows / 2) + 25 * (c - cols / 2)).astype(np.int64)
    path.write_bytes(bytes(header) + np.asarray(counts, dtype=">i4").tobytes())
    return path


def datx(path: Path, surface: np.ndarray | None = None, *, unit: str = "NanoMeters",
         wavelength_m: float | None = 632.8e-9) -> Path:
    """A ``.datx`` with ``Measurement/Surface`` in ``unit`` (a random 32 x 32 map by default)."""
    values = np.random.default_rng(1).normal(size=(32, 32)) if surface is None else surface
    with h5py.File(path, "w") as h5:
        node = h5.create_dataset("Measurement/Surface", data=values)
        node.attrs["Unit"] = unit
        if wavelength_m is not None:
            node.attrs["Wavelength"] = wavelength_m
    return path


def datx_declaring(path: Path, rows: int, cols: int) -> Path:
    """A few-kilobyte ``.datx`` whose surface declares rows x cols float32 values (chunks never written)."""
    with h5py.File(path, "w") as h5:
        node = h5.create_dataset("Measurement/Surface", shape=(rows, cols), dtype="f4",
                                 chunks=(min(rows, 1000), min(cols, 1000)), compression="gzip")
        node.attrs["Unit"] = "NanoMeters"
    return path


def datx_string_surface(path: Path) -> Path:
    """A ``.datx`` whose surface is a scalar string."""
    with h5py.File(path, "w") as h5:
        h5.create_dataset("Measurement/Surface", data="not a surface").attrs["Unit"] = "NanoMeters"
    return path


def datx_link_loop(path: Path) -> Path:
    """A ``.datx`` whose ``Measurement/Surface`` is a soft link to itself."""
    with h5py.File(path, "w") as h5:
        h5.create_group("Measurement")["Surface"] = h5py.SoftLink("/Measurement/Surface")
    return path


def datx_dangling_link(path: Path) -> Path:
    """A ``.datx`` whose ``Measurement/Surface`` links to a file that does not exist."""
    with h5py.File(path, "w") as h5:
        h5.create_group("Measurement")["Surface"] = h5py.ExternalLink("missing.h5", "/data")
    return path


def fourd_h5(path: Path, data: np.ndarray | None = None, *, wavelength: str = "632.8 nm") -> Path:
    """A 4D ``measurement0/genraw`` file."""
    with h5py.File(path, "w") as h5:
        node = h5.create_group("measurement0/genraw")
        node.attrs["wavelength"] = wavelength
        node.create_dataset("data", data=np.zeros((16, 16), np.float32) if data is None else data)
    return path


def fourd_declaring(path: Path, rows: int, cols: int) -> Path:
    """A small 4D ``.h5`` whose map declares rows x cols values never written."""
    with h5py.File(path, "w") as h5:
        node = h5.create_group("measurement0/genraw")
        node.attrs["wavelength"] = "632.8 nm"
        node.create_dataset("data", shape=(rows, cols), dtype="f4", chunks=(256, 256), compression="gzip")
    return path


def png_declaring(path: Path, width: int, height: int, colour_type: int = 2) -> Path:
    """A PNG whose header declares width x height (RGB by default) followed by one tiny IDAT."""
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, colour_type, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\x00" * 64))
                     + chunk(b"IEND", b""))
    return path


def fringes(folder: Path, count: int = 4, *, identical: bool = False, size: int = 128) -> list[Path]:
    """``count`` phase-shifted fringe frames (a disk of fringes on a dark halo), as PNG files."""
    rows, cols = np.indices((size, size))
    disk = np.hypot(rows - size / 2, cols - size / 2) < size * 0.4
    paths = []
    for k in range(count):
        step = 0.0 if identical else 2 * np.pi * k / count
        frame = np.where(disk, 120 + 100 * np.cos(0.3 * cols + 0.002 * rows**2 + step), 10)
        path = folder / f"frame{k}.png"
        cv2.imwrite(str(path), frame.astype(np.uint8))
        paths.append(path)
    return paths


def npy(path: Path, array: np.ndarray) -> Path:
    """``array`` saved to exactly ``path``."""
    with open(path, "wb") as stream:
        np.save(stream, array)
    return path


def npy_declaring(path: Path, shape: tuple[int, ...]) -> Path:
    """A ``.npy`` header declaring ``shape`` float64 with only 8 bytes of data."""
    header = {"descr": "<f8", "fortran_order": False, "shape": shape}
    with open(path, "wb") as stream:
        np.lib.format.write_array_header_1_0(stream, header)
        stream.write(b"\x00" * 8)
    return path
