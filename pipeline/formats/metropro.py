"""Reader for Zygo MetroPro ``.dat`` interferometer files (binary).

MetroPro ``.dat`` (:func:`read_metropro_dat`)
---------------------------------------------
Written from the layout in the MetroPro Reference Guide [1]_, appendix "Data File Format". A
file is a big-endian header followed by the intensity ("acquired", ``ac_``) arrays and then
the phase ("connected", ``cn_``) array:

=============  ==========  ===========  ================================================
header format  magic       header size  checked on
=============  ==========  ===========  ================================================
1              0x881B036F  834 bytes    the real file in the ``zygo-dat`` data
2              0x881B0370  834 bytes    synthetic copies only
3              0x881B0371  4096 bytes   synthetic copies only
=============  ==========  ===========  ================================================

Formats 2 and 3 keep the fields of format 1 at the same offsets and only append fields, and
every field read here lies in the first 834 bytes, so one table (``_METROPRO_FIELDS``, byte
offsets from 0) serves all three. Each field of the table was checked against the real
format-1 file (values in the tests). The arrays:

* intensity: ``ac_n_buckets`` frames of ``ac_height`` rows x ``ac_width`` columns, unsigned
  16-bit, row-major, ``ac_n_bytes = 2 * buckets * rows * cols`` bytes; values run from 0 to
  ``ac_range``. Invalid pixels carry a marker at the top of the 16-bit range: 65535
  (``INVALID_INTENSITY``) counts as invalid, and so does any value above ``ac_range``
  (which also covers readers that put the marker threshold a little below 65535). The
  real file has no invalid intensity pixel, so this rule is unchecked on real data.
* phase: ``cn_height`` rows x ``cn_width`` columns, signed 32-bit, row-major,
  ``cn_n_bytes = 4 * rows * cols`` bytes, placed at (``cn_org_x``, ``cn_org_y``) = (col, row)
  of the camera frame; values ``>= 2147483640`` (``INVALID_PHASE``, ``invalid_phs``) are
  invalid [1]_.

Phase to length [1]_: ``waves = value * S * O / R`` and ``length = waves * wavelength_in``,
with ``S = intf_scale_factor``, ``O = obliquity_factor`` and ``R`` from ``phase_res``
(0 -> 4096, 1 -> 32768, 2 -> 131072). ``S`` is the number of waves of the measured quantity
per fringe: 0.5 for a surface measured in reflection (double pass: one fringe is half a wave
of surface height), 1 for a transmitted wavefront. The result is therefore the quantity the
instrument was set up to report, surface height when ``S = 0.5`` (as in the real file), and
the reader does not rescale it. The ``sign`` field is decoded but not applied (see
:func:`read_metropro_dat`).

Zygo Mx ``.datx`` files are read by :mod:`wavestack.pipeline.formats.datx`.

References
----------
.. [1] Zygo Corporation, *MetroPro Reference Guide* (OMP-0347), appendix "Data File Format":
   header formats 1-3, field offsets and types, ``invalid_phs``, phase-resolution rule.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .errors import InputError
from .limits import check_allocation
from .metropro_header import METROPRO_MAGIC, _parse_header, MetroProHeader

__all__ = [
    "INVALID_INTENSITY",
    "INVALID_PHASE",
    "METROPRO_MAGIC",
    "MetroProHeader",
    "MetroProMap",
    "read_metropro_dat",
]

logger = logging.getLogger(__name__)

INVALID_PHASE = 2147483640  # phase values >= this are invalid ("invalid_phs")
INVALID_INTENSITY = 65535  # intensity marker of an invalid pixel


@dataclass(frozen=True, eq=False)
class MetroProMap:
    """A MetroPro measurement: header, phase as a length map, intensity.

    Attributes
    ----------
    header : MetroProHeader
    phase_nm : NDArray[np.float64], shape (phase_height, phase_width)
        The phase converted to length, in nanometres, NaN where invalid; row 0 is the top
        row of the phase window. Surface height when ``header.intf_scale_factor`` is 0.5,
        transmitted wavefront when 1 (see the module notes). Read-only.
    intensity : NDArray[np.uint16] or None
        Raw camera counts, shape (intensity_height, intensity_width) for one frame or
        (buckets, intensity_height, intensity_width) for several; invalid pixels keep
        their marker (see :attr:`intensity_valid`). None when the file has none. Read-only.
    valid_count : int
        Number of valid (finite) phase pixels.
    """

    header: MetroProHeader
    phase_nm: NDArray[np.float64]
    intensity: NDArray[np.uint16] | None
    valid_count: int

    @property
    def intensity_valid(self) -> NDArray[np.bool_] | None:
        """True where the intensity is a count (not 65535, not above ``intensity_range``)."""
        if self.intensity is None:
            return None
        valid = self.intensity != INVALID_INTENSITY
        if self.header.intensity_range > 0:
            valid &= self.intensity <= self.header.intensity_range
        return valid


# ----------------------------------------------------------------------------- MetroPro .dat


def _check_sizes(path: Path, header: MetroProHeader, file_bytes: int) -> None:
    frame_pixels = header.intensity_width * header.intensity_height
    intensity_bytes = 2 * header.intensity_buckets * frame_pixels
    phase_bytes = 4 * header.phase_width * header.phase_height
    if header.intensity_bytes != intensity_bytes:
        raise InputError(
            f"{path}: inconsistent MetroPro header: {header.intensity_buckets} intensity "
            f"frame(s) of {header.intensity_height} x {header.intensity_width} need "
            f"{intensity_bytes} bytes, but ac_n_bytes says {header.intensity_bytes}"
        )
    if header.phase_bytes != phase_bytes:
        raise InputError(
            f"{path}: inconsistent MetroPro header: a {header.phase_height} x {header.phase_width} "
            f"phase array needs {phase_bytes} bytes, but cn_n_bytes says {header.phase_bytes}"
        )
    if phase_bytes == 0:
        raise InputError(f"{path}: the MetroPro file holds no phase data (phase array of 0 pixels)")
    needed = header.header_size + intensity_bytes + phase_bytes
    if file_bytes < needed:
        raise InputError(
            f"{path}: truncated MetroPro file: {file_bytes} bytes, but the header "
            f"({header.header_size} bytes) announces {intensity_bytes} bytes of intensity and "
            f"{phase_bytes} bytes of phase, {needed} bytes in all"
        )
    if file_bytes > needed:
        logger.debug("%s: %d bytes after the phase data ignored", path, file_bytes - needed)


# A wavelength in metres outside (1 nm, 1 mm) is not an interferometer's (X-rays to far infrared).
_WAVELENGTH_M = (1e-9, 1e-3)


def _length_per_count_nm(path: Path, header: MetroProHeader) -> float:
    if not _WAVELENGTH_M[0] < header.wavelength_in < _WAVELENGTH_M[1]:
        raise InputError(
            f"{path}: MetroPro wavelength_in {header.wavelength_in} m is not a wavelength; expected "
            f"between {_WAVELENGTH_M[0]:g} and {_WAVELENGTH_M[1]:g} m"
        )
    scale = header.intf_scale_factor * header.obliquity_factor / header.phase_resolution
    nm_per_count = scale * header.wavelength_in * 1e9
    if not (np.isfinite(nm_per_count) and nm_per_count > 0):
        raise InputError(
            f"{path}: cannot convert MetroPro phase to length: intf_scale_factor "
            f"{header.intf_scale_factor}, obliquity_factor {header.obliquity_factor}, "
            f"wavelength_in {header.wavelength_in} m must all be positive"
        )
    return nm_per_count


def read_metropro_dat(path: str | Path, *, max_bytes: int | None = None) -> MetroProMap:
    """Read a Zygo MetroPro ``.dat`` file (header format 1, 2 or 3).

    Parameters
    ----------
    path : str or Path
        The ``.dat`` file.
    max_bytes : int, optional
        The most this reader may allocate (default: the memory budget of
        :mod:`wavestack.pipeline.formats.limits`): the file's bytes plus the float64 phase map,
        which the header's byte counts tie to the file's size.

    Returns
    -------
    MetroProMap
        ``phase_nm`` of shape (phase_height, phase_width) in nanometres with NaN for invalid
        phase (values ``>= 2147483640``), converted as ``value * S * O / R *
        wavelength_in``; ``intensity`` as raw uint16 counts of shape (rows, cols), or
        (buckets, rows, cols) when the file holds several frames, or None when it holds none.

    Raises
    ------
    InputError
        If the file is missing, its magic number is not a MetroPro one, its header format
        is not 1, 2 or 3, its header is inconsistent (format, size, byte counts, phase
        resolution flag, non-positive scale factors, a wavelength outside 1 nm to 1 mm), it is
        shorter than the header says its arrays need, or larger than the memory budget. The
        message names the file.

    Notes
    -----
    The ``sign`` field (MetroPro's data-sign setting) is decoded but not applied: whether
    the stored phase already carries the sign could not be checked (the real file has
    ``sign = 0``); a file with ``sign != 0`` is read as stored and a warning is logged.

    References
    ----------
    .. [1] Zygo Corporation, *MetroPro Reference Guide* (OMP-0347), appendix "Data File
       Format".
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        # the file is read whole, then its phase counts become float64: about 3 times its size
        check_allocation(path, "file", (path.stat().st_size,), 3, max_bytes)
        data = path.read_bytes()
    except OSError as error:
        raise InputError(f"{path}: cannot read the file ({error})") from None
    header = _parse_header(path, data)
    _check_sizes(path, header, len(data))
    nm_per_count = _length_per_count_nm(path, header)
    if header.sign != 0:
        logger.warning(
            "%s: MetroPro sign field is %d; phase read as stored, not inverted", path, header.sign
        )

    offset = header.header_size
    intensity: NDArray[np.uint16] | None = None
    if header.intensity_bytes:
        shape = (header.intensity_buckets, header.intensity_height, header.intensity_width)
        frames = np.frombuffer(data, dtype=">u2", count=int(np.prod(shape)), offset=offset)
        intensity = frames.reshape(shape).astype(np.uint16)
        intensity = intensity[0] if header.intensity_buckets == 1 else intensity
        intensity.flags.writeable = False
        offset += header.intensity_bytes

    shape = (header.phase_height, header.phase_width)
    counts = np.frombuffer(data, dtype=">i4", count=shape[0] * shape[1], offset=offset)
    counts = counts.reshape(shape)
    valid = counts < INVALID_PHASE
    phase_nm = np.where(valid, counts.astype(np.float64) * nm_per_count, np.nan)
    phase_nm.flags.writeable = False
    valid_count = int(np.count_nonzero(valid))
    logger.debug(
        "%s: MetroPro phase %s, %d valid pixels, %.6g nm per count",
        path, shape, valid_count, nm_per_count,
    )
    return MetroProMap(
        header=header, phase_nm=phase_nm, intensity=intensity, valid_count=valid_count
    )
