"""Reading maps and masks from files: the one place where wavestack touches file formats.

Every reader raises :class:`InputError`, whose message names the file and what was expected,
so that a command line can print it as one line.
"""

from __future__ import annotations

import io
import tokenize
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .errors import InputError
from .images import decode_image
from .limits import check_allocation
from .measured import MEASURED_MAP_SUFFIXES, check_magnitude, read_measured_map, unsupported_reason

__all__ = ["InputError", "load_map", "load_mask"]

_IMAGE_SUFFIXES = {".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp"}


def _existing(path: str | Path) -> Path:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    return path


_NPY_HEADER_BYTES = 65536  # numpy writes headers of at most a few hundred bytes; its reader refuses > 10000


def _load_npy(path: Path) -> NDArray:
    """The array, once its header's shape is within the memory budget and the file holds its bytes.

    The header is parsed from at most the file's first 64 KiB held in memory, so a header that
    declares a huge length of itself cannot make the reader ask for that many bytes.
    """
    try:
        with open(path, "rb") as stream:
            head = io.BytesIO(stream.read(_NPY_HEADER_BYTES))
        version = np.lib.format.read_magic(head)
        if version not in ((1, 0), (2, 0), (3, 0)):
            raise ValueError(f"format version {version[0]}.{version[1]} is none of 1.0, 2.0, 3.0")
        read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                       else np.lib.format.read_array_header_2_0)
        shape, _, dtype = read_header(head)
        if dtype.hasobject:
            raise ValueError(f"dtype {dtype} holds Python objects")
        check_allocation(path, ".npy array", shape, dtype.itemsize + 8)
        stored = path.stat().st_size - head.tell()
        needed = int(np.prod(shape)) * dtype.itemsize
        if stored < needed:
            raise InputError(f"{path}: truncated .npy file: its header declares {shape} {dtype} ({needed} bytes), "
                             f"the file holds {stored}")
        return np.load(path, allow_pickle=False)
    except InputError:
        raise
    except (ValueError, OSError, EOFError, TypeError, SyntaxError, tokenize.TokenError) as error:
        raise InputError(f"{path}: not a readable .npy array ({_one_line(error)})") from None


def _one_line(error: BaseException) -> str:
    """An exception's message on one line."""
    return " ".join(str(error).split()) or type(error).__name__


def load_map(path: str | Path) -> NDArray[np.float64]:
    """Read a wavefront or surface map from a ``.npy`` file or an instrument file.

    Parameters
    ----------
    path : str or Path
        A ``.npy`` file holding a 2-D real array (NaN marks pixels outside the aperture), or a
        measured map: Zygo ``.dat`` or ``.datx``, 4D Technology 4Sight ``.h5``
        (:func:`~wavestack.pipeline.formats.measured.read_measured_map`).

    Returns
    -------
    ndarray of float64, shape (rows, cols)
        The ``.npy`` values as stored; an instrument file's map in nanometres, NaN where the
        file marks a pixel invalid.

    Raises
    ------
    InputError
        If the file is missing or unreadable, of an unsupported kind (said first), not 2-D,
        not real-valued, has no finite value or a value beyond ``MAX_MAP_MAGNITUDE``, or
        declares an array larger than the memory budget or than the file holds.
    """
    path = _existing(path)
    suffix = path.suffix.lower()
    if suffix in MEASURED_MAP_SUFFIXES:
        return np.array(read_measured_map(path).map_nm)
    if suffix != ".npy":
        reason = unsupported_reason(path, images=False)
        raise InputError(reason or f"{path}: expected a .npy map (2-D float array, NaN outside)")
    array = _load_npy(path)
    if array.ndim != 2 or 0 in array.shape:
        raise InputError(f"{path}: expected a 2-D map, got an array of shape {array.shape}")
    if not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise InputError(f"{path}: expected real numbers, got dtype {array.dtype}")
    array = array.astype(np.float64)
    finite = np.isfinite(array)
    if not finite.any():
        raise InputError(f"{path}: every value is NaN or infinite; expected a map with valid pixels")
    check_magnitude(path, array[finite])
    return array


def load_mask(path: str | Path, shape: tuple[int, int] | None = None) -> NDArray[np.bool_]:
    """Read a mask (non-zero = valid) from a ``.npy`` array or an image (PNG, TIFF, ...).

    Parameters
    ----------
    path : str or Path
        The file; an image with several channels counts a pixel valid if any channel is
        non-zero.
    shape : (rows, cols), optional
        The shape the mask must have (that of the map it belongs to).

    Returns
    -------
    ndarray of bool, shape (rows, cols)

    Raises
    ------
    InputError
        If the file is missing or unreadable, not 2-D, or of the wrong shape.
    """
    path = _existing(path)
    suffix = path.suffix.lower()
    if suffix == ".npy":
        array = _load_npy(path)
        if array.dtype == object or np.iscomplexobj(array):
            raise InputError(f"{path}: expected a real or boolean mask, got dtype {array.dtype}")
    elif suffix in _IMAGE_SUFFIXES:
        array = decode_image(path)
        if array.ndim == 3:
            array = array.any(axis=2)
    else:
        raise InputError(f"{path}: expected a .npy array or an image ({', '.join(sorted(_IMAGE_SUFFIXES))})")
    if array.ndim != 2:
        raise InputError(f"{path}: expected a 2-D mask, got an array of shape {array.shape}")
    if shape is not None and array.shape != tuple(shape):
        raise InputError(f"{path}: mask shape {array.shape} does not match the map's {tuple(shape)}")
    return array != 0
