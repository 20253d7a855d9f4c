"""Tests for wavestack.pipeline.formats.metropro and .datx: MetroPro .dat on the real file, .datx on synthetic files.

The real file is ``zygo-dat/valid_zygo_dat_file.dat`` in the shared data (header format 1);
corrupted and truncated variants are written to ``tmp_path``, never over the original.
There is no real .datx file: the .datx tests write their own HDF5 files following the layout
documented in :func:`wavestack.pipeline.formats.datx.read_datx`.
"""

from __future__ import annotations

import struct
from pathlib import Path

import h5py
import numpy as np
import pytest

from wavestack.pipeline.formats.maps import InputError
from wavestack.pipeline.formats.metropro import INVALID_PHASE, MetroProMap, read_metropro_dat
from wavestack.pipeline.formats.datx import DatxMap, read_datx

from shared_data import DATA

DAT = DATA / "zygo-dat" / "valid_zygo_dat_file.dat"
HEADER = 834
INTENSITY_BYTES = 640 * 480 * 2
PHASE_BYTES = 425 * 432 * 4

pytestmark = pytest.mark.skipif(not DAT.is_file(), reason="real MetroPro file not available")


@pytest.fixture(scope="module")
def real() -> MetroProMap:
    return read_metropro_dat(DAT)


def _copy(tmp_path: Path, data: bytes, name: str = "copy.dat") -> Path:
    path = tmp_path / name
    path.write_bytes(data)
    return path


def _patched(offset: int, fmt: str, value: object) -> bytes:
    data = bytearray(DAT.read_bytes())
    struct.pack_into(">" + fmt, data, offset, value)
    return bytes(data)


# ----------------------------------------------------------------------------- real .dat


def test_real_header_fields(real: MetroProMap) -> None:
    h = real.header
    assert (h.magic_number, h.header_format, h.header_size) == (0x881B036F, 1, 834)
    assert h.software_type == 1 and h.software_version == (8, 3, 5)
    assert h.software_date == "Mon Jan 04 08:42:09 2010"
    # ac_width = 640 columns, ac_height = 480 rows: the README's "640x480" is width x height.
    assert (h.intensity_width, h.intensity_height, h.intensity_buckets) == (640, 480, 1)
    assert h.intensity_origin == (0, 0) and h.intensity_range == 255
    # cn_width = 425 columns, cn_height = 432 rows at (col, row) = (139, 38).
    assert (h.phase_width, h.phase_height, h.phase_origin) == (425, 432, (139, 38))
    assert (h.intensity_bytes, h.phase_bytes) == (INTENSITY_BYTES, PHASE_BYTES)
    assert (h.camera_width, h.camera_height) == (640, 480)
    assert h.intf_scale_factor == 0.5 and h.obliquity_factor == 1.0
    assert h.phase_res == 1 and h.phase_resolution == 32768
    assert h.wavelength_in == 6.328e-07 and h.wavelength_nm == pytest.approx(632.8)
    assert h.lateral_resolution_m == pytest.approx(0.118e-3, rel=0.01)
    assert h.camera_res == pytest.approx(1.179242e-4, rel=1e-6)
    assert h.pixel_width == h.pixel_height == 7.4e-6  # camera pixel pitch
    assert h.sign == 0 and h.source == 0 and h.sys_serial == 62398 and h.phase_avg_cnt == 10
    assert h.obj_name == "Sm Aperture" and h.comment == "" and h.refractive_index == 1.0
    assert h.measured_at.isoformat() == "2015-04-24T19:54:52+00:00"


def test_real_arrays(real: MetroProMap) -> None:
    assert real.phase_nm.shape == (432, 425) and real.phase_nm.dtype == np.float64
    assert real.intensity is not None
    assert real.intensity.shape == (480, 640) and real.intensity.dtype == np.uint16
    assert real.valid_count == 136359
    assert 134_000 <= real.valid_count <= 138_000
    assert np.count_nonzero(np.isfinite(real.phase_nm)) == real.valid_count
    assert real.intensity_valid is not None and real.intensity_valid.all()
    assert real.intensity.max() <= real.header.intensity_range
    assert not real.phase_nm.flags.writeable and not real.intensity.flags.writeable


def test_real_phase_conversion_and_statistics(real: MetroProMap) -> None:
    data = DAT.read_bytes()
    row, col = 200, 210  # a valid pixel near the centre
    (count,) = struct.unpack_from(">i", data, HEADER + INTENSITY_BYTES + 4 * (row * 425 + col))
    assert count < INVALID_PHASE
    assert real.phase_nm[row, col] == pytest.approx(count * 0.5 * 1.0 / 32768 * 632.8, rel=1e-6)
    (corner,) = struct.unpack_from(">i", data, HEADER + INTENSITY_BYTES)
    assert corner >= INVALID_PHASE and np.isnan(real.phase_nm[0, 0])
    residual = real.phase_nm - np.nanmean(real.phase_nm)
    assert np.sqrt(np.nanmean(residual**2)) == pytest.approx(44.59, abs=0.01)
    assert np.nanmax(residual) - np.nanmin(residual) == pytest.approx(330.70, abs=0.01)


def test_real_phase_window_sits_on_the_bright_pupil(real: MetroProMap) -> None:
    """Orientation and origin: valid phase lies where the intensity shows the pupil."""
    col, row = real.header.phase_origin
    assert real.intensity is not None
    window = real.intensity[row : row + 432, col : col + 425].astype(float)
    valid = np.isfinite(real.phase_nm)
    assert window[valid].mean() > 2.5 * window[~valid].mean()


# ----------------------------------------------------------------------------- bad .dat


def test_missing_file_raises(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such file"):
        read_metropro_dat(tmp_path / "absent.dat")


@pytest.mark.parametrize("size", [0, 6, HEADER - 1, HEADER + 100, HEADER + INTENSITY_BYTES, -1])
def test_truncated_copy_raises_naming_the_file(tmp_path: Path, size: int) -> None:
    data = DAT.read_bytes()
    path = _copy(tmp_path, data[: size if size >= 0 else len(data) + size], "truncated.dat")
    with pytest.raises(InputError, match="truncated") as info:
        read_metropro_dat(path)
    assert str(path) in str(info.value)


def test_corrupted_magic_raises(tmp_path: Path) -> None:
    path = _copy(tmp_path, _patched(0, "I", 0x12345678), "bad_magic.dat")
    with pytest.raises(InputError, match="magic number 0x12345678") as info:
        read_metropro_dat(path)
    assert str(path) in str(info.value)


def test_unsupported_header_format_is_named(tmp_path: Path) -> None:
    path = _copy(tmp_path, _patched(4, "H", 4))
    with pytest.raises(InputError, match="header format 4 is not supported"):
        read_metropro_dat(path)


@pytest.mark.parametrize(
    ("offset", "fmt", "value", "message"),
    [
        (4, "H", 3, "is that of header format 1"),  # format field disagrees with magic
        (6, "I", 4096, "header size field says 4096"),
        (60, "I", 1234, "ac_n_bytes says 1234"),
        (72, "I", 1234, "cn_n_bytes says 1234"),
        (218, "h", 7, "phase_res flag 7"),
        (164, "f", 0.0, "cannot convert MetroPro phase to length"),
    ],
)
def test_inconsistent_header_raises(
    tmp_path: Path, offset: int, fmt: str, value: object, message: str
) -> None:
    path = _copy(tmp_path, _patched(offset, fmt, value))
    with pytest.raises(InputError, match=message):
        read_metropro_dat(path)


def test_header_format_3_layout_reads_the_same_data(tmp_path: Path, real: MetroProMap) -> None:
    """Format 3: other magic, 4096-byte header, same field offsets (synthetic, not a real file)."""
    data = bytearray(DAT.read_bytes())
    struct.pack_into(">IHI", data, 0, 0x881B0371, 3, 4096)
    converted = bytes(data[:HEADER]) + bytes(4096 - HEADER) + bytes(data[HEADER:])
    result = read_metropro_dat(_copy(tmp_path, converted, "format3.dat"))
    assert result.header.header_format == 3 and result.header.header_size == 4096
    np.testing.assert_array_equal(result.phase_nm, real.phase_nm)


def test_several_intensity_buckets_give_a_stack(tmp_path: Path, real: MetroProMap) -> None:
    data = bytearray(DAT.read_bytes())
    struct.pack_into(">HHI", data, 56, 2, 255, 2 * INTENSITY_BYTES)  # buckets, range, bytes
    frames = bytes(data[HEADER : HEADER + INTENSITY_BYTES])
    doubled = bytes(data[:HEADER]) + frames + frames + bytes(data[HEADER + INTENSITY_BYTES :])
    result = read_metropro_dat(_copy(tmp_path, doubled, "two_buckets.dat"))
    assert result.intensity is not None and result.intensity.shape == (2, 480, 640)
    np.testing.assert_array_equal(result.intensity[1], real.intensity)
    np.testing.assert_array_equal(result.phase_nm, real.phase_nm)


def test_invalid_intensity_marker_is_reported(tmp_path: Path) -> None:
    path = _copy(tmp_path, _patched(HEADER + 2 * (10 * 640 + 20), "H", 65535))
    result = read_metropro_dat(path)
    assert result.intensity is not None and result.intensity[10, 20] == 65535
    assert result.intensity_valid is not None
    assert not result.intensity_valid[10, 20] and result.intensity_valid.sum() == 640 * 480 - 1


# ----------------------------------------------------------------------------- .datx

_STR = h5py.string_dtype()
_VLEN = h5py.vlen_dtype(np.float64)


def _converter(
    category: str, unit: str, parameters: list[float], *, vlen: bool = True, scalar: bool = False
) -> np.ndarray:
    """A Zygo-style converter: compound (Category, BaseUnit, Parameters)."""
    param_type = (_VLEN,) if vlen else ("<f8", (len(parameters),))
    dtype = np.dtype([("Category", _STR), ("BaseUnit", _STR), ("Parameters", *param_type)])
    value = np.empty((), dtype) if scalar else np.empty(1, dtype)
    record = (category, unit, np.asarray(parameters, dtype=np.float64))
    if scalar:
        value[()] = record
    else:
        value[0] = record
    return value


def _write_datx(
    path: Path,
    surface: np.ndarray,
    unit: str,
    *,
    no_data: float,
    group: str = "Measurement",
    z_parameters: tuple[float, ...] = (0.0, 632.8e-9, 0.5, 1.0),
    dx: float = 1.25e-5,
    vlen: bool = True,
    scalar: bool = False,
    intensity: np.ndarray | None = None,
) -> None:
    with h5py.File(path, "w") as h5:
        node = h5.create_dataset(f"{group}/Surface", data=surface)
        kinds = {"vlen": vlen, "scalar": scalar}
        node.attrs["Z Converter"] = _converter("HeightCat", unit, list(z_parameters), **kinds)
        node.attrs["X Converter"] = _converter("LateralCat", "Pixels", [0.0, dx, 0.0, 0.0], **kinds)
        node.attrs["No Data"] = np.array([no_data], dtype=surface.dtype)
        node.attrs["Unit"] = np.array([unit], dtype=_STR)
        if intensity is not None:
            inten = h5.create_dataset(f"{group}/Intensity", data=intensity)
            inten.attrs["No Data"] = np.array([65535], dtype=np.uint16)


def _surface(no_data: float) -> np.ndarray:
    values = np.arange(12, dtype=np.float32).reshape(3, 4) * np.float32(0.25)
    values[1, 2] = no_data
    values[2, 0] = np.nan
    return values


def test_datx_micrometres_with_no_data(tmp_path: Path) -> None:
    no_data = float(np.finfo(np.float32).max)
    surface = _surface(no_data)
    intensity = np.full((3, 4), 100, dtype=np.uint16)
    intensity[0, 0] = 65535
    path = tmp_path / "synthetic.datx"
    _write_datx(path, surface, "MicroMeters", no_data=no_data, intensity=intensity)
    result = read_datx(path)
    assert isinstance(result, DatxMap)
    expected = surface.astype(np.float64) * 1e3
    expected[1, 2] = expected[2, 0] = np.nan
    np.testing.assert_allclose(result.surface_nm, expected, equal_nan=True)
    assert np.count_nonzero(np.isnan(result.surface_nm)) == 2
    assert result.wavelength_nm == pytest.approx(632.8)
    assert result.lateral_resolution_m == pytest.approx(1.25e-5)
    assert result.intensity is not None and np.isnan(result.intensity[0, 0])
    assert np.nanmax(result.intensity) == 100
    assert result.attributes["Unit"] == "MicroMeters"
    assert result.attributes["Z Converter"][:2] == ("HeightCat", "MicroMeters")
    assert not result.surface_nm.flags.writeable


@pytest.mark.parametrize(
    ("vlen", "scalar"), [(True, False), (False, False), (False, True), (True, True)]
)
def test_datx_fringes_and_converter_variants(tmp_path: Path, vlen: bool, scalar: bool) -> None:
    """Fringes -> nm via wavelength * S * O; converters (1,)-shaped or scalar, vlen or fixed."""
    no_data = -1.0e10
    surface = _surface(no_data).astype(np.float64)
    path = tmp_path / "fringes.datx"
    _write_datx(path, surface, "Fringes", no_data=no_data, group="Data", vlen=vlen, scalar=scalar)
    result = read_datx(path)
    expected = surface * 632.8 * 0.5 * 1.0
    expected[1, 2] = expected[2, 0] = np.nan
    np.testing.assert_allclose(result.surface_nm, expected, equal_nan=True)
    assert result.intensity is None


def test_datx_surface_in_a_group_of_one_dataset(tmp_path: Path) -> None:
    path = tmp_path / "grouped.datx"
    surface = np.ones((2, 3))
    with h5py.File(path, "w") as h5:
        node = h5.create_dataset("Data/Surface/{0C9D2A4E}", data=surface)
        node.attrs["Unit"] = "NanoMeters"
        node.attrs["No Data"] = 1e300
        h5["Data"].attrs["Wavelength"] = 5.461e-7  # on the parent group
    result = read_datx(path)
    np.testing.assert_array_equal(result.surface_nm, surface)
    assert result.wavelength_nm == pytest.approx(546.1)
    assert result.lateral_resolution_m is None


def test_datx_missing_surface_is_named(tmp_path: Path) -> None:
    path = tmp_path / "no_surface.datx"
    with h5py.File(path, "w") as h5:
        h5.create_dataset("Measurement/Intensity", data=np.zeros((2, 2)))
    with pytest.raises(InputError, match="no surface data.*'Measurement/Surface'") as info:
        read_datx(path)
    assert str(path) in str(info.value)


def test_datx_missing_unit_and_unknown_unit(tmp_path: Path) -> None:
    path = tmp_path / "no_unit.datx"
    with h5py.File(path, "w") as h5:
        h5.create_dataset("Measurement/Surface", data=np.zeros((2, 2)))
    with pytest.raises(InputError, match="neither a 'Z Converter' nor a 'Unit'"):
        read_datx(path)
    path = tmp_path / "furlongs.datx"
    _write_datx(path, np.zeros((2, 2)), "Furlongs", no_data=1.0)
    with pytest.raises(InputError, match="unknown surface unit 'Furlongs'"):
        read_datx(path)


def test_datx_not_hdf5_and_missing(tmp_path: Path) -> None:
    path = tmp_path / "garbage.datx"
    path.write_bytes(b"not an HDF5 file at all")
    with pytest.raises(InputError, match="not a readable HDF5"):
        read_datx(path)
    with pytest.raises(InputError, match="no such file"):
        read_datx(tmp_path / "absent.datx")
