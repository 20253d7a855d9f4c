"""Reading camera frames (interferograms) from image files as 2-D arrays.

Frames are read with OpenCV (``cv2.imread`` with ``IMREAD_UNCHANGED``) [1]_, which keeps the
stored depth (8- or 16-bit integers, 32-bit float TIFF) and ignores EXIF orientation, so the
array is the sensor's pixel grid as stored.

Colour files are reduced to one channel. When the colour channels are identical the first
one is taken as it is. Otherwise the frame is converted to luma with the ITU-R BT.601
weights ``Y = 0.299 R + 0.587 G + 0.114 B`` [2]_ (the weights OpenCV's ``COLOR_BGR2GRAY``
uses), rounded back to the stored integer type. For a grey picture stored as a colour JPEG
this is the right choice and not an approximation: JPEG stores that very luma (its Y
channel) and decoding to RGB adds rounding differences of a count or so between channels
(the real interferograms in the shared ``psi-mirror-654nm`` data differ by up to 3 counts
between channels in nearly every pixel, although they were meant to be grey), so the BT.601
luma recovers the stored Y within one count. For a frame whose channels really differ
(more than 2 % of full scale) a warning is logged, since mixing the channels of a colour
camera is a choice the caller may want to know about. An alpha channel is dropped.

References
----------
.. [1] OpenCV documentation, ``cv2.imread`` and ``ImreadModes`` (``IMREAD_UNCHANGED``).
.. [2] ITU-R Recommendation BT.601-7, "Studio encoding parameters of digital television
   for standard 4:3 and wide-screen 16:9 aspect ratios" (2011), luma equation.
"""

from __future__ import annotations

import logging
import os
import re
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from .errors import InputError
from .image_header import declared_size
from .limits import check_allocation, memory_budget_bytes

__all__ = ["BT601_WEIGHTS_BGR", "FRAME_SUFFIXES", "read_frame", "read_frame_set"]

logger = logging.getLogger(__name__)

FRAME_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp")
BT601_WEIGHTS_BGR = (0.114, 0.587, 0.299)  # luma weights in OpenCV's channel order B, G, R
_COLOUR_WARNING_FRACTION = 0.02  # channel difference (fraction of full scale) that is logged
# What the decoders say about a file they decoded only in part (libjpeg: "Premature end of JPEG
# file", "Corrupt JPEG data"; libpng: "... error"; OpenCV: "buffer is incomplete"); warnings such
# as libpng's "iCCP: known incorrect sRGB profile" are not damage.
_DAMAGE = re.compile(r"premature|corrupt|incomplete|truncat|error", re.IGNORECASE)
_LUMA_BLOCK_PIXELS = 1 << 18  # colour is converted in row blocks of about this many pixels (6 MiB float64)


def _full_scale(image: NDArray) -> float:
    if np.issubdtype(image.dtype, np.integer):
        return float(np.iinfo(image.dtype).max)
    finite = image[np.isfinite(image)]
    return float(np.ptp(finite)) if finite.size else 0.0


def _to_gray(path: Path, image: NDArray) -> NDArray:
    """Reduce an (rows, cols, channels) colour image to one channel (module notes)."""
    channels = image.shape[2]
    if channels == 1:
        return image[:, :, 0]
    if channels == 2:  # grey + alpha
        return image[:, :, 0]
    colour = image[:, :, :3]
    first = colour[:, :, 0]
    if np.array_equal(first, colour[:, :, 1]) and np.array_equal(first, colour[:, :, 2]):
        return first.copy()
    gray = np.empty(first.shape, dtype=image.dtype)
    spread = 0.0
    rows = max(1, _LUMA_BLOCK_PIXELS // max(1, first.shape[1]))
    for start in range(0, first.shape[0], rows):  # float64 in row blocks, never the whole frame
        block = colour[start:start + rows].astype(np.float64)
        spread = max(spread, float(np.nanmax(block.max(axis=2) - block.min(axis=2))))
        gray[start:start + rows] = _luma(block, image.dtype)
    coloured = spread > _COLOUR_WARNING_FRACTION * _full_scale(image)
    logger.log(
        logging.WARNING if coloured else logging.DEBUG,
        "%s: colour channels differ by up to %g; converted to BT.601 luma", path, spread,
    )
    return gray


def _luma(block: NDArray[np.float64], dtype: np.dtype) -> NDArray:
    """BT.601 luma of a (rows, cols, 3) BGR block, rounded back to ``dtype`` for integers."""
    luma = block @ np.asarray(BT601_WEIGHTS_BGR)
    if np.issubdtype(dtype, np.integer):
        info = np.iinfo(dtype)
        return np.clip(np.rint(luma), info.min, info.max).astype(dtype)
    return luma.astype(dtype)


def read_frame(path: str | Path, *, max_bytes: int | None = None) -> NDArray:
    """Read one camera frame as a 2-D array.

    Parameters
    ----------
    path : str or Path
        A PNG, TIFF, JPEG or BMP file (suffixes in :data:`FRAME_SUFFIXES`), grey or colour,
        8 or 16 bit, or 32-bit float TIFF.
    max_bytes : int, optional
        The most the frame may make this reader allocate, checked from the header before
        anything is decoded: the decoded image plus one float64 copy of the frame, which the
        analysis makes (default: the memory budget of
        :mod:`wavestack.pipeline.formats.limits`).

    Returns
    -------
    ndarray, shape (rows, cols)
        The stored dtype: uint8, uint16 (or another integer type the file holds), float32
        for a float TIFF. Colour files are reduced to one channel as the module notes say.

    Raises
    ------
    InputError
        If the file is missing, has another suffix, has a header that does not say its size,
        declares a frame larger than ``max_bytes``, cannot be decoded as an image, or does
        not hold a single 2-D frame (grey, grey + alpha, BGR or BGRA).

    References
    ----------
    .. [1] OpenCV documentation, ``cv2.imread``.
    .. [2] ITU-R Recommendation BT.601-7 (2011), luma equation.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    if path.suffix.lower() not in FRAME_SUFFIXES:
        raise InputError(f"{path}: expected an image file ({', '.join(FRAME_SUFFIXES)})")
    image = decode_image(path, max_bytes)
    if image.ndim == 3 and image.shape[2] in (1, 2, 3, 4):
        image = _to_gray(path, image)
    if image.ndim != 2:
        raise InputError(
            f"{path}: expected a 2-D frame (grey or colour), got an array of shape {image.shape}"
        )
    return image


def decode_image(path: Path, max_bytes: int | None = None) -> NDArray:
    """The image as OpenCV decodes it (``IMREAD_UNCHANGED``), once its header's size is within budget.

    Raises
    ------
    InputError
        If the file cannot be read, its header does not say its size, it declares more than
        ``max_bytes`` (decoded image plus one float64 copy), or it does not decode.
    """
    budget = memory_budget_bytes() if max_bytes is None else max_bytes
    try:
        check_allocation(path, "image file", (path.stat().st_size,), 1, budget)
        data = path.read_bytes()
    except OSError as error:
        raise InputError(f"{path}: cannot read the file ({error.strerror})") from None
    size = declared_size(data)
    if size is None:
        raise InputError(f"{path}: not a readable image (no PNG, JPEG, TIFF or BMP header that gives its size: "
                         "another kind of file, or damaged or truncated)")
    check_allocation(path, "image", (size.height, size.width),
                     size.channels * size.bytes_per_sample + 8, budget - len(data))
    image, complaints = _decode_quietly(data)
    if image is None or image.size == 0:
        raise InputError(f"{path}: not a readable image" + (f" ({complaints})" if complaints else ""))
    if _DAMAGE.search(complaints):  # decoded in part: the rest would be filled in, not measured
        raise InputError(f"{path}: damaged image, decoded only in part ({complaints})")
    if complaints:
        logger.warning("%s: %s", path, complaints)
    return image


def _decode_quietly(data: bytes) -> tuple[NDArray | None, str]:
    """``cv2.imdecode`` with what the decoders print on file descriptor 2 taken into the result.

    libpng and OpenCV write their complaints about a damaged file ("libpng error: IDAT:
    incorrect data check") to the process's standard error, beside the command's one line; they
    are captured here and returned as one line for the caller's message. The descriptor is
    redirected for the duration of the decode only, so another thread's writes to standard error
    during it would land in the message too (the command line decodes files in one thread).
    """
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED) if data else None
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        sink.seek(0)
        text = sink.read(4096).decode("utf-8", errors="replace")
    return image, "; ".join(line.strip() for line in text.splitlines() if line.strip())


def read_frame_set(paths: Sequence[str | Path], *, max_bytes: int | None = None) -> NDArray:
    """Read several frames of equal shape and dtype into one stack.

    Parameters
    ----------
    paths : sequence of str or Path
        The frames, in the order wanted (e.g. of the phase steps).
    max_bytes : int, optional
        The most the set may make this reader allocate, shared equally by the frames (see
        :func:`read_frame`).

    Returns
    -------
    ndarray, shape (N, rows, cols)
        The frames as :func:`read_frame` returns them, stacked along axis 0.

    Raises
    ------
    InputError
        If ``paths`` is empty, a frame cannot be read (see :func:`read_frame`), or a frame's
        shape or dtype differs from the first frame's; the message names the first such
        file, the first file, and both shapes (or dtypes).
    """
    paths = [Path(p) for p in paths]
    if not paths:
        raise InputError("read_frame_set: no files given; expected at least one frame")
    per_frame = (memory_budget_bytes() if max_bytes is None else max_bytes) // len(paths)
    first = read_frame(paths[0], max_bytes=per_frame)
    stack = np.empty((len(paths), *first.shape), dtype=first.dtype)
    stack[0] = first
    for index, path in enumerate(paths[1:], start=1):
        frame = read_frame(path, max_bytes=per_frame)
        if frame.shape != first.shape:
            raise InputError(
                f"{path}: frame shape {frame.shape} differs from the shape {first.shape} "
                f"of {paths[0]}"
            )
        if frame.dtype != first.dtype:
            raise InputError(
                f"{path}: frame dtype {frame.dtype} differs from the dtype {first.dtype} "
                f"of {paths[0]}"
            )
        stack[index] = frame
    return stack
