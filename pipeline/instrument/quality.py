"""The per-pixel data-quality mask: which measured pixels inside the aperture the fit may use.

Interferometer software does not fit what it cannot trust. Inside the aperture a pixel is marked

* **low modulation**: its fringe modulation is below ``min_modulation`` times the mean over the
  fitted pixels (its phase noise is that many times the typical one), or it was left out of the
  fit when the aperture was adopted for the same reason (a dust dropout or a speck of rim the
  detection's closing took in);
* **saturated**: it reaches the camera's full scale in a frame of the set (the fringe is clipped,
  and the phase formula's assumption of a sinusoid fails there);
* **untrusted fringe order**: after unwrapping, it differs from a good 4-neighbour by more than half
  a fringe (pi). A residue of the wrapped phase always leaves such a jump on one of its loop's
  edges (the unwrapped differences around a loop sum to zero, the wrapped ones to 2 pi), so this
  catches residues too; both pixels of a jump are marked, since either may be the wrong one (a
  jump against a pixel of low modulation or saturated marks that one only). And where the jumps
  cut part of the aperture off from its main body, the part's order relative to the rest is not
  known: every pixel outside the largest region of its aperture component that no jump crosses is
  marked as well (pixels marked for their signal alone still link the regions: a saturated fringe
  or a dropout does not cut the order, a jump does);
* **clipped** (by :mod:`~wavestack.pipeline.instrument.statistics`): its fit residual is a spike;
* **rim**: it lies in the band along the aperture's edge that the phase method cannot measure
  (the carrier method: within one fringe period of the edge, where the sideband filter mixes the
  outside in; left out when the aperture is adopted, :mod:`~.tracking`).

Marked pixels are NaN in the map that is fitted, shown and reported: never filled, never fitted,
never in a statistic. :class:`PixelQuality` counts them; the flags map says which is which
(bits :data:`LOW_MODULATION`, :data:`SATURATED`, :data:`UNTRUSTED_ORDER`, :data:`CLIPPED`,
:data:`RIM`; :data:`OUTSIDE` outside the aperture).

The counts are the instrument's, not the interferometer's: a Shack-Hartmann processor counts its
lenslets (samples) the same way.

Cost: one compiled call walks the fit grid four times (the mean modulation; the signal marks,
reading each frame at the grid's pixels; the jumps; the masked map) and, only when a jump was
found, the regions between them are labelled (OpenCV) and the map masked again. See
``benchmarks/bench_live_numbers.py``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import cv2
import numba
import numpy as np
from numpy.typing import NDArray

from .settings import QualitySettings

__all__ = ["CLIPPED", "LOW_MODULATION", "OUTSIDE", "RIM", "PixelQuality", "QualityMask", "SATURATED",
           "UNTRUSTED_ORDER", "full_scale_of", "mark_quality"]

LOW_MODULATION: Final = 1
SATURATED: Final = 2
UNTRUSTED_ORDER: Final = 4
CLIPPED: Final = 8
RIM: Final = 16
OUTSIDE: Final = 128


@dataclass(frozen=True)
class PixelQuality:
    """What the data-quality mask left out of one result, in samples inside the aperture.

    Samples are the pixels of the fit grid for an interferometer (lenslets for a Shack-Hartmann
    sensor). A sample may carry several marks; each count counts the samples with that mark.

    Attributes
    ----------
    inside : int
        Samples inside the aperture.
    used : int
        Samples the fit and every statistic used.
    low_modulation, saturated, untrusted_order, clipped, rim : int
    """

    inside: int
    used: int
    low_modulation: int = 0
    saturated: int = 0
    untrusted_order: int = 0
    clipped: int = 0
    rim: int = 0

    @property
    def excluded(self) -> int:
        """Samples inside the aperture left out."""
        return self.inside - self.used

    def to_json(self) -> dict[str, int]:
        return {"inside": self.inside, "used": self.used, "excluded": self.excluded,
                "low_modulation": self.low_modulation, "saturated": self.saturated,
                "untrusted_order": self.untrusted_order, "clipped": self.clipped, "rim": self.rim}

    @classmethod
    def of(cls, flags: NDArray[np.uint8]) -> PixelQuality:
        """The counts of a flags map (one compiled pass)."""
        return cls(*(int(n) for n in _count_flags(flags)))


@dataclass(frozen=True, eq=False)
class QualityMask:
    """One set's marks on the fit grid, and the map they leave.

    Attributes
    ----------
    flags : ndarray of uint8, shape (rows, cols)
        0 for a used pixel, :data:`OUTSIDE` outside the aperture, else the marks (module notes).
    waves : ndarray of float64, shape (rows, cols)
        The unwrapped phase in waves, NaN outside the aperture and at every marked pixel.
    """

    flags: NDArray[np.uint8]
    waves: NDArray[np.float64]


def full_scale_of(frames: Sequence[NDArray[np.generic]], saturation_counts: float | None) -> float:
    """The saturation level of these frames: the configured one, else their integer type's largest value.

    Returns ``inf`` for float frames without a configured level (nothing is saturated).
    """
    if saturation_counts is not None:
        return float(saturation_counts)
    dtype = np.asarray(frames[0]).dtype
    return float(np.iinfo(dtype).max) if dtype.kind in "iu" else math.inf


def mark_quality(phase: NDArray[np.float64], modulation: NDArray[np.floating], frames: Sequence[NDArray[np.generic]],
                 step: int, adopted: NDArray[np.uint8], components: tuple[NDArray[np.int32], int],
                 settings: QualitySettings) -> QualityMask:
    """The data-quality marks of one set (module notes) and the map they leave.

    Parameters
    ----------
    phase : ndarray of float64, shape (rows, cols)
        Unwrapped phase on the fit grid, radians (NaN off ``fitted``).
    modulation : ndarray, shape (rows * step, cols * step) or larger
        Fringe modulation at full resolution (any units); sampled every ``step``-th pixel.
    frames : sequence of ndarray
        The set's frames at full resolution (saturation is looked for at the fit grid's pixels).
    step : int
        The fit grid's decimation.
    adopted : ndarray of uint8, shape (rows, cols)
        The marks fixed when the aperture was adopted: :data:`OUTSIDE` outside it, 0 on the pixels
        the fitter was built on, :data:`LOW_MODULATION` or :data:`RIM` on those left out.
    components : (ndarray of int32, int)
        Labels (4-connectivity, 0 elsewhere) of the connected components of the fitted pixels and
        their count + 1.
    settings : QualitySettings

    Returns
    -------
    QualityMask

    Example
    -------
    >>> phase = np.zeros((5, 5)); phase[2, 2] = 2 * np.pi  # one pixel a whole fringe off
    >>> adopted = np.zeros((5, 5), np.uint8)  # every pixel inside and fitted
    >>> labels = (np.ones((5, 5), np.int32), 2)
    >>> mask = mark_quality(phase, np.ones((5, 5)), [np.zeros((5, 5), np.uint8)], 1, adopted, labels,
    ...                     QualitySettings())
    >>> PixelQuality.of(mask.flags).untrusted_order, bool(np.isnan(mask.waves[2, 2]))  # it and its 4 neighbours
    (5, True)
    """
    flags = np.empty(adopted.shape, dtype=np.uint8)
    waves = np.empty(adopted.shape, dtype=np.float64)
    full_scale = full_scale_of(frames, settings.saturation_counts)
    looked_at = tuple(np.asarray(f) for f in frames)
    if len({f.dtype for f in looked_at}) > 1:  # one compiled walk reads them all: one type
        looked_at = tuple(f.astype(np.float64) for f in looked_at)
    jumps = _mark(phase, np.asarray(modulation), looked_at, full_scale, step, adopted, float(settings.min_modulation),
                  bool(settings.check_fringe_order), flags, waves)
    if jumps:  # the regions the jumps cut off: their order against the main body is not known
        linked = ((adopted == 0) & ((flags & UNTRUSTED_ORDER) == 0)).view(np.uint8)
        count, labels = cv2.connectedComponents(linked, connectivity=4, ltype=cv2.CV_32S)
        _keep_main_regions(labels, count, components[0], components[1], flags)
        _masked_waves(phase, flags, waves)
    return QualityMask(flags, waves)


@numba.njit(nogil=True, cache=True)
def _mark(phase, modulation, frames, full_scale, step, adopted, fraction, check_order, flags, waves
          ):  # type: ignore[no-untyped-def]
    """The marks of one set in one compiled call: the adoption's, low modulation, saturation (a frame of
    ``frames`` at full scale on the grid; none when that is infinite), the jumps; and, when no jump was
    found, the masked map. Returns the pixels the jumps marked."""
    rows, cols = adopted.shape
    total = 0.0
    count = 0
    for r in range(rows):
        for c in range(cols):
            if adopted[r, c] == 0:
                total += modulation[r * step, c * step]
                count += 1
    level = fraction * total / max(count, 1)
    for r in range(rows):
        for c in range(cols):
            mark = adopted[r, c]
            if mark == 0:
                if modulation[r * step, c * step] < level:
                    mark |= 1
                if full_scale < np.inf:
                    for k in range(len(frames)):
                        if frames[k][r * step, c * step] >= full_scale:
                            mark |= 2
                            break
            flags[r, c] = mark
    jumps = _mark_jumps(phase, adopted, flags) if check_order else 0
    if jumps == 0:
        _masked_waves(phase, flags, waves)
    return jumps


@numba.njit(nogil=True, cache=True)
def _mark_jumps(phase, adopted, flags):  # type: ignore[no-untyped-def]
    """Mark the ends of every jump of more than pi between fitted 4-neighbours; returns the pixels marked.

    A jump between two pixels of good signal marks both (either may be wrong); a jump against a
    pixel already marked for its signal marks that one only (its phase is the suspect).
    """
    rows, cols = flags.shape
    marked = 0
    for r in range(rows):
        for c in range(cols):
            if adopted[r, c] != 0:
                continue
            for dr, dc in ((0, 1), (1, 0)):
                rr, cc = r + dr, c + dc
                if rr >= rows or cc >= cols or adopted[rr, cc] != 0:
                    continue
                if abs(phase[r, c] - phase[rr, cc]) <= math.pi:
                    continue
                weak_here, weak_there = flags[r, c] & 3, flags[rr, cc] & 3
                for pr, pc, mark in ((r, c, weak_here or not weak_there), (rr, cc, weak_there or not weak_here)):
                    if mark and not flags[pr, pc] & 4:
                        flags[pr, pc] |= 4
                        marked += 1
    return marked


@numba.njit(nogil=True, cache=True)
def _keep_main_regions(labels, count, aperture_labels, aperture_count, flags):  # type: ignore[no-untyped-def]
    """Mark the good pixels outside the largest good region of their aperture component."""
    size = np.zeros(count, dtype=np.int64)
    owner = np.zeros(count, dtype=np.int64)
    rows, cols = labels.shape
    for r in range(rows):
        for c in range(cols):
            g = labels[r, c]
            if g > 0:
                size[g] += 1
                owner[g] = aperture_labels[r, c]
    best = np.zeros(max(aperture_count, 1), dtype=np.int64)
    best_size = np.zeros(max(aperture_count, 1), dtype=np.int64)
    for g in range(1, count):
        if size[g] > best_size[owner[g]]:
            best_size[owner[g]] = size[g]
            best[owner[g]] = g
    for r in range(rows):
        for c in range(cols):
            g = labels[r, c]
            if g > 0 and best[owner[g]] != g:
                flags[r, c] |= 4


@numba.njit(nogil=True, cache=True)
def _masked_waves(phase, flags, waves):  # type: ignore[no-untyped-def]
    """``phase / 2 pi`` where the flags are 0, NaN elsewhere."""
    rows, cols = flags.shape
    scale = 1.0 / (2.0 * math.pi)
    for r in range(rows):
        for c in range(cols):
            waves[r, c] = phase[r, c] * scale if flags[r, c] == 0 else np.nan


@numba.njit(nogil=True, cache=True)
def _count_flags(flags):  # type: ignore[no-untyped-def]
    """(inside, used, low modulation, saturated, untrusted order, clipped, rim) of a flags map."""
    counts = np.zeros(7, dtype=np.int64)
    for value in flags.ravel():
        if value == 128:
            continue
        counts[0] += 1
        if value == 0:
            counts[1] += 1
        for k, bit in enumerate((1, 2, 4, 8, 16)):
            if value & bit:
                counts[2 + k] += 1
    return counts
