"""Property tests of the file readers: any bytes either parse or raise InputError naming the file.

Each reader gets valid files mutated by Hypothesis (bytes overwritten, truncated, extended) and
plain arbitrary bytes. The properties: the reader returns or raises :class:`InputError` whose
message names the file, never another exception; and it never allocates more than the file
justifies: each call is given ``max_bytes`` (a multiple of the file's size), and the peak of
Python-tracked allocations during the call (numpy's arrays are tracked by ``tracemalloc``) stays
within it.
"""

from __future__ import annotations

import tracemalloc
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import hostile_files as hf
from fuzz import fuzz_settings
from wavestack.pipeline.formats import InputError, load_map, load_mask, read_4d, read_datx, read_frame
from wavestack.pipeline.formats import read_metropro_dat

# A reader may hold the file and a few float64 copies of what it declares; 64 bytes per file byte
# (8 float64 copies of a file made of single bytes) plus 1 MiB for fixed costs (HDF5's caches are
# not numpy arrays, so they are not counted here).
_PER_FILE_BYTE = 64
_FIXED = 1 << 20
# A damaged .datx can hang the HDF5 library (about 1 in 1500 mutated seeds did); the reader's
# child process is killed after this long and the file refused. Far above a healthy read (~20 ms).
_HDF5_TIMEOUT_S = 10.0


def _mutated(data: bytes) -> st.SearchStrategy[bytes]:
    """``data`` with some bytes overwritten, then cut or extended."""
    @st.composite
    def build(draw: st.DrawFn) -> bytes:
        buffer = bytearray(data)
        for _ in range(draw(st.integers(0, 8))):
            at = draw(st.integers(0, len(buffer) - 1))
            chunk = draw(st.binary(min_size=1, max_size=8))
            buffer[at:at + len(chunk)] = chunk
        cut = draw(st.one_of(st.none(), st.integers(0, len(buffer))))
        if cut is not None:
            del buffer[cut:]
        return bytes(buffer) + draw(st.binary(max_size=16))
    return build()


def _check(reader: Callable[..., object], path: Path, data: bytes, **options: object) -> None:
    path.write_bytes(data)
    limit = _PER_FILE_BYTE * len(data) + _FIXED
    tracemalloc.start()
    try:
        reader(path, max_bytes=limit, **options)
    except InputError as error:
        assert str(path) in str(error), error
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    assert peak <= limit + _FIXED, (peak, limit)


def _valid(builder: Callable[[Path], Path], folder: Path, name: str) -> bytes:
    return builder(folder / name).read_bytes()


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Where the examples are written (one file per test, overwritten by each example)."""
    return tmp_path_factory.mktemp("fuzz")


@pytest.fixture(scope="module")
def seeds(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """Valid files of each format, the starting points of the mutations."""
    folder = tmp_path_factory.mktemp("seeds")
    rng = np.random.default_rng(5)
    frame = rng.integers(0, 255, (24, 32), dtype=np.uint8)
    images = {suffix: cv2.imencode(suffix, frame)[1].tobytes() for suffix in (".png", ".jpg", ".tif", ".bmp")}
    images[".colour.png"] = cv2.imencode(".png", rng.integers(0, 255, (12, 16, 3), dtype=np.uint8))[1].tobytes()
    return {
        "dat": _valid(lambda p: hf.metropro_dat(p, shape=(12, 10)), folder, "seed.dat"),
        "datx": _valid(lambda p: hf.datx(p, rng.normal(size=(12, 10))), folder, "seed.datx"),
        "h5": _valid(lambda p: hf.fourd_h5(p, rng.normal(size=(12, 10)).astype(np.float32)), folder, "seed.h5"),
        "npy": _valid(lambda p: hf.npy(p, rng.normal(size=(12, 10))), folder, "seed.npy"),
        **{f"image{suffix}": data for suffix, data in images.items()},
    }


@fuzz_settings(300)
@given(data=st.data())
def test_metropro_dat_mutated_bytes(seeds: dict[str, bytes], folder: Path, data: st.DataObject) -> None:
    _check(read_metropro_dat, folder / "f.dat", data.draw(_mutated(seeds["dat"])))


@fuzz_settings(300)
@given(raw=st.binary(max_size=2048))
def test_metropro_dat_arbitrary_bytes(folder: Path, raw: bytes) -> None:
    _check(read_metropro_dat, folder / "f.dat", raw)


@fuzz_settings(300)
@given(data=st.data())
def test_datx_mutated_bytes(seeds: dict[str, bytes], folder: Path, data: st.DataObject) -> None:
    _check(read_datx, folder / "f.datx", data.draw(_mutated(seeds["datx"])), timeout_s=_HDF5_TIMEOUT_S)


@fuzz_settings(300)
@given(data=st.data())
def test_4d_h5_mutated_bytes(seeds: dict[str, bytes], folder: Path, data: st.DataObject) -> None:
    _check(read_4d, folder / "f.h5", data.draw(_mutated(seeds["h5"])), timeout_s=_HDF5_TIMEOUT_S)


@fuzz_settings(300)
@given(data=st.data(), kind=st.sampled_from([".png", ".jpg", ".tif", ".bmp", ".colour.png"]))
def test_image_mutated_bytes(seeds: dict[str, bytes], folder: Path, data: st.DataObject, kind: str) -> None:
    suffix = kind.rsplit(".", 1)[-1]
    _check(read_frame, folder / f"f.{suffix}", data.draw(_mutated(seeds[f"image{kind}"])))


@fuzz_settings(300)
@given(raw=st.binary(max_size=1024), suffix=st.sampled_from(["png", "jpg", "tif", "bmp"]))
def test_image_arbitrary_bytes(folder: Path, raw: bytes, suffix: str) -> None:
    _check(read_frame, folder / f"f.{suffix}", raw)


def _load_map(path: Path, max_bytes: int) -> object:
    return load_map(path)


@fuzz_settings(300)
@given(data=st.data())
def test_npy_map_and_mask_mutated_bytes(seeds: dict[str, bytes], folder: Path, data: st.DataObject) -> None:
    # load_map and load_mask take the memory budget, not max_bytes: a mutated header declaring a
    # huge shape must still be refused from the file's length before anything is allocated
    raw = data.draw(_mutated(seeds["npy"]))
    path = folder / "f.npy"
    for reader in (lambda p, max_bytes: load_map(p), lambda p, max_bytes: load_mask(p)):
        _check(reader, path, raw)
