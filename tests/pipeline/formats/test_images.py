"""Tests for wavestack.pipeline.formats.images: frames from PNG/TIFF/JPEG/BMP files.

Round trips use files written to ``tmp_path``; the real interferograms in
``psi-mirror-654nm`` in the shared data (800 x 600 RGB JPEGs meant to be grey) are read as
they are.
"""

from __future__ import annotations

import logging
from pathlib import Path

import cv2
import numpy as np
import pytest

from wavestack.pipeline.formats.images import read_frame, read_frame_set
from wavestack.pipeline.formats.maps import InputError

from shared_data import DATA

PSI = DATA / "psi-mirror-654nm"


def _write(path: Path, image: np.ndarray) -> Path:
    assert cv2.imwrite(str(path), image)
    return path


def _ramp(dtype: type, rows: int = 5, cols: int = 7) -> np.ndarray:
    top = np.iinfo(dtype).max
    return (np.arange(rows * cols).reshape(rows, cols) * (top // (rows * cols))).astype(dtype)


@pytest.mark.parametrize(
    ("name", "dtype"),
    [
        ("f.png", np.uint8),
        ("f.png", np.uint16),
        ("f.tif", np.uint16),
        ("f.tiff", np.uint8),
        ("f.bmp", np.uint8),
    ],
)
def test_lossless_round_trips(tmp_path: Path, name: str, dtype: type) -> None:
    image = _ramp(dtype)
    frame = read_frame(_write(tmp_path / name, image))
    assert frame.dtype == dtype and frame.shape == (5, 7)
    np.testing.assert_array_equal(frame, image)


def test_float_tiff_keeps_float(tmp_path: Path) -> None:
    image = np.linspace(-1.5, 2.5, 35, dtype=np.float32).reshape(5, 7)
    frame = read_frame(_write(tmp_path / "f.tif", image))
    assert frame.dtype == np.float32
    np.testing.assert_array_equal(frame, image)


def test_equal_channels_give_that_channel(tmp_path: Path) -> None:
    grey = _ramp(np.uint8)
    frame = read_frame(_write(tmp_path / "c.png", np.dstack([grey, grey, grey])))
    assert frame.dtype == np.uint8
    np.testing.assert_array_equal(frame, grey)


def test_unequal_channels_give_bt601_luma(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    bgr = np.zeros((2, 3, 3), dtype=np.uint16)
    bgr[..., 0], bgr[..., 1], bgr[..., 2] = 1000, 20000, 60000  # B, G, R
    with caplog.at_level(logging.WARNING, logger="wavestack.pipeline.formats.images"):
        frame = read_frame(_write(tmp_path / "colour.png", bgr))
    assert frame.dtype == np.uint16
    luma = round(0.114 * 1000 + 0.587 * 20000 + 0.299 * 60000)
    np.testing.assert_array_equal(frame, np.full((2, 3), luma))
    assert "BT.601" in caplog.text


def test_alpha_channel_is_dropped(tmp_path: Path) -> None:
    grey = _ramp(np.uint8)
    alpha = np.full_like(grey, 255)
    frame = read_frame(_write(tmp_path / "a.png", np.dstack([grey, grey, grey, alpha])))
    np.testing.assert_array_equal(frame, grey)


def test_bad_files_raise(tmp_path: Path) -> None:
    garbage = tmp_path / "garbage.png"
    garbage.write_bytes(b"\x89PNG but not really an image")
    with pytest.raises(InputError, match="not a readable image") as info:
        read_frame(garbage)
    assert str(garbage) in str(info.value)
    with pytest.raises(InputError, match="no such file"):
        read_frame(tmp_path / "absent.png")
    other = tmp_path / "frame.npy"
    other.write_bytes(b"")
    with pytest.raises(InputError, match="expected an image file"):
        read_frame(other)


def test_frame_set_and_mismatches(tmp_path: Path) -> None:
    frames = [_ramp(np.uint8) + k for k in range(3)]
    paths = [_write(tmp_path / f"f{k}.png", f) for k, f in enumerate(frames)]
    stack = read_frame_set(paths)
    assert stack.shape == (3, 5, 7) and stack.dtype == np.uint8
    np.testing.assert_array_equal(stack, np.stack(frames))

    odd = _write(tmp_path / "odd.png", _ramp(np.uint8, 6, 7))
    with pytest.raises(InputError) as info:
        read_frame_set([paths[0], paths[1], odd, paths[2]])
    message = str(info.value)
    assert str(odd) in message and str(paths[0]) in message
    assert "(6, 7)" in message and "(5, 7)" in message

    deep = _write(tmp_path / "deep.png", _ramp(np.uint16))
    with pytest.raises(InputError, match="dtype uint16 differs"):
        read_frame_set([paths[0], deep])
    with pytest.raises(InputError, match="no files"):
        read_frame_set([])


# ----------------------------------------------------------------------------- real JPEGs


@pytest.mark.skipif(not PSI.is_dir(), reason="real interferograms not available")
def test_real_jpeg_frames() -> None:
    names = (PSI / "files.txt").read_text().split()
    stack = read_frame_set([PSI / name for name in names])
    assert stack.shape == (12, 600, 800) and stack.dtype == np.uint8
    # The decoded channels are not exactly equal (JPEG rounding); the luma read is the
    # JPEG's stored Y channel (libjpeg's grey decode) within one count.
    for name, frame in zip(names, stack, strict=True):
        colour = cv2.imread(str(PSI / name), cv2.IMREAD_UNCHANGED)
        assert colour.shape == (600, 800, 3)
        y = cv2.imread(str(PSI / name), cv2.IMREAD_GRAYSCALE)
        assert np.abs(frame.astype(int) - y).max() <= 1
    single = read_frame(PSI / "Image197.jpg")
    assert single.shape == (600, 800) and single.dtype == np.uint8
