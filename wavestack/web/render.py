"""A map as the browser gets it: downsampled by block means, coloured, encoded as a PNG, with its outline.

The map (waves, NaN outside the aperture) is averaged over ``factor x factor`` blocks so that its
longer side is at most ``max_side`` pixels; a block with fewer than half its pixels inside the
aperture is outside (so the outline does not grow by the rims of partly covered blocks). The
colour scale runs from the smallest to the largest block mean: every colour on the page is a value
the map has. Colours are the Turbo map (Mikhailov 2019, an improved rainbow like the ones
interferometer programs show), taken from OpenCV; NaN is transparent. The outline is traced on the
downsampled mask with OpenCV's border following (Suzuki & Abe 1985), outer edges and holes.

Pixels the data-quality mask left out (their value NaN, their flag set: low modulation,
saturated, untrusted fringe order, clipped, rim) are not hidden: every block holding one is painted in
:data:`LEFT_OUT_COLOUR`, a magenta the Turbo scale never shows, so a dropout is seen as a dropout and
never as a value.
"""

from __future__ import annotations

import math
import time

import cv2
import numpy as np
from numpy.typing import NDArray

from wavestack.web.view import MapImage, Polygon

__all__ = ["COLOURS", "LEFT_OUT_COLOUR", "downsample", "render_map"]

_LUT_BGR = cv2.applyColorMap(np.arange(256, dtype=np.uint8).reshape(1, 256), cv2.COLORMAP_TURBO)[0]
#: The colour scale from ``vmin`` to ``vmax``, 256 ``#rrggbb`` strings (the page draws its colour bar with them).
COLOURS: tuple[str, ...] = tuple(f"#{r:02x}{g:02x}{b:02x}" for b, g, r in _LUT_BGR.tolist())
#: The colour of a block holding a pixel the quality mask left out (``#rrggbb``).
LEFT_OUT_COLOUR = "#ff00ff"
_LEFT_OUT_BGR = (255, 0, 255)
_OUTSIDE_FLAG = 128  # the quality flags' value outside the aperture (pipeline.instrument.quality.OUTSIDE)


def downsample(values: NDArray[np.floating], factor: int) -> NDArray[np.float64]:
    """Block means of ``values`` over ``factor x factor`` blocks, NaN where under half a block is finite.

    Parameters
    ----------
    values : ndarray (H, W)
        NaN outside the aperture.
    factor : int
        Block side, pixels (>= 1); a partial block at the right or bottom edge counts its own pixels.

    Returns
    -------
    ndarray (ceil(H / factor), ceil(W / factor))

    Example
    -------
    >>> downsample(np.array([[1.0, 3.0], [np.nan, 5.0]]), 2)
    array([[3.]])
    """
    if factor < 1:
        raise ValueError(f"factor: expected an integer >= 1, got {factor}")
    h, w = values.shape
    rows, cols = -(-h // factor), -(-w // factor)
    padded = values
    if (rows * factor, cols * factor) != (h, w):
        padded = np.full((rows * factor, cols * factor), np.nan)
        padded[:h, :w] = values
    finite = np.isfinite(padded)
    # sums over the last axis first: contiguous reductions (a 4-D sum over axes (1, 3) is 3x slower)
    total = np.where(finite, padded, 0.0).reshape(rows, factor, cols, factor).sum(axis=3).sum(axis=1)
    count = finite.reshape(rows, factor, cols, factor).sum(axis=3, dtype=np.int32).sum(axis=1)
    size = np.full((rows, cols), factor * factor)
    size[-1, :] = (h - (rows - 1) * factor) * factor  # the partial blocks' own pixel counts
    size[:, -1] = factor * (w - (cols - 1) * factor)
    size[-1, -1] = (h - (rows - 1) * factor) * (w - (cols - 1) * factor)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = total / count
    means[count * 2 < size] = np.nan
    return means


def _outline(inside: NDArray[np.bool_]) -> tuple[Polygon, ...]:
    contours, _ = cv2.findContours(inside.astype(np.uint8), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_SIMPLE)
    polygons = []
    for contour in contours:
        simple = cv2.approxPolyDP(contour, 0.5, True).reshape(-1, 2)
        polygons.append(tuple((float(x) + 0.5, float(y) + 0.5) for x, y in simple))
    return tuple(polygons)


def render_map(values: NDArray[np.floating], *, units: str, title: str, seq: int, max_side: int = 200,
               flags: NDArray[np.uint8] | None = None) -> MapImage:
    """The false-colour PNG of a map, its colour scale, RMS, PV and outline (module notes).

    Parameters
    ----------
    values : ndarray (H, W)
        The map in ``units``, NaN outside the aperture; not modified.
    units : str
    title : str
    seq : int
        The render's number.
    max_side : int
        Longest side of the PNG, pixels.
    flags : ndarray of uint8 (H, W), optional
        The quality marks of the map's pixels: blocks holding a left-out pixel are painted
        :data:`LEFT_OUT_COLOUR` (module notes).

    Returns
    -------
    MapImage
        With every value NaN: an empty (transparent) image and NaN scale.

    Example
    -------
    >>> y, x = np.mgrid[-1:1:64j, -1:1:64j]
    >>> image = render_map(np.where(x**2 + y**2 < 1, x, np.nan), units="waves", title="tilt", seq=1, max_side=32)
    >>> (image.width, image.height, image.png[:4])
    (32, 32, b'\\x89PNG')
    """
    started = time.perf_counter()
    factor = max(1, math.ceil(max(values.shape) / max_side))
    full = np.asarray(values, dtype=np.float64)
    small = downsample(full, factor)
    inside = np.isfinite(small)
    finite_full = full[np.isfinite(full)]
    rms = float(np.sqrt(np.mean((finite_full - finite_full.mean()) ** 2))) if finite_full.size else math.nan
    pv = float(finite_full.max() - finite_full.min()) if finite_full.size else math.nan
    vmin = float(small[inside].min()) if inside.any() else math.nan
    vmax = float(small[inside].max()) if inside.any() else math.nan
    span = vmax - vmin if inside.any() and vmax > vmin else 1.0
    levels = np.zeros(small.shape, dtype=np.uint8)
    if inside.any():
        levels[inside] = np.clip(np.rint((small[inside] - vmin) / span * 255.0), 0, 255).astype(np.uint8)
    bgra = np.zeros(small.shape + (4,), dtype=np.uint8)
    bgra[..., :3] = _LUT_BGR[levels]
    bgra[..., 3] = np.where(inside, 255, 0)
    left_out = 0
    if flags is not None:
        marked = (flags != 0) & (flags != _OUTSIDE_FLAG)
        left_out = int(np.count_nonzero(marked))
        if left_out:
            blocks = downsample(marked.astype(np.float64), factor) > 0  # NaN nowhere: any marked pixel counts
            bgra[blocks, :3] = _LEFT_OUT_BGR
            bgra[blocks, 3] = 255
    ok, encoded = cv2.imencode(".png", bgra)
    if not ok:  # OpenCV reports failure by a flag; a map this size never fails to encode
        raise RuntimeError(f"PNG encoding of a {small.shape} map failed")
    return MapImage(seq=seq, png=encoded.tobytes(), width=small.shape[1], height=small.shape[0], factor=factor,
                    vmin=vmin, vmax=vmax, colours=COLOURS[::17],
                    units=units, rms=rms, pv=pv, outline=_outline(inside), title=title,
                    render_ms=(time.perf_counter() - started) * 1e3, left_out=left_out)
