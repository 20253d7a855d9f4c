"""Will the camera resolve the fringes? The steepest fringe slope over the misalignment range, from the model.

A phase-shifting interferometer samples the wavefront once per camera pixel: a slope above half a
wave per pixel (two pi radians of fringe phase across two pixels) aliases, and the unwrapped map
is then wrong everywhere past the first aliased pixel. Before the loop trusts the station's maps
it bounds the slope over the stated misalignment range with the design model, to first order:
per pixel, ``|grad W(0)| + sum_k |grad W(+r_k) - grad W(-r_k)| / 2`` over the degrees of freedom
``k`` with ranges ``r_k`` (a secant over the whole range, which includes the curvature a tangent
at zero would miss), each map with the reference's tilt removed as the interferometer removes it
(:func:`~wavestack.pipeline.telescope.centring_tilt`), the gradient the larger of the
neighbour differences along a row and a column (waves per pixel). The bound is the worst over
the pixels and the field points.

On this bench (1 mm pixels, +-0.3 mm / +-0.03 deg) the tilt alone reaches 0.9 waves per pixel
and the rest stays near 0.1: the reference's tilt is what makes the range measurable, not a
finer camera (which would have to be 3-4 times finer per axis for the same range).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline.telescope import DOFS, HexapodPose, ReferenceTilt, WavefrontModel, centring_tilt

__all__ = ["MAX_SLOPE_WAVES_PER_PX", "NYQUIST_WAVES_PER_PX", "fringe_slope_bound", "pixel_slope"]

#: Half a wave per pixel: the fringe slope at which a camera samples a fringe twice.
NYQUIST_WAVES_PER_PX = 0.5
#: The bound the session accepts: half the Nyquist slope, leaving the other half to what the
#: first-order bound omits (second-order terms) and to the phase noise of a PSI frame, which
#: makes a spatial unwrapper slip well before the Nyquist slope is reached.
MAX_SLOPE_WAVES_PER_PX = NYQUIST_WAVES_PER_PX / 2


def pixel_slope(waves: NDArray[np.floating], null_tilt: bool = True) -> NDArray[np.float64]:
    """Per pixel, the larger neighbour difference along a row and a column, waves per pixel (NaN off the map).

    Example
    -------
    >>> w = ReferenceTilt(0.2, 0.0).plane((4, 6)) + np.arange(4)[:, None] ** 2 * 0.1
    >>> round(float(np.nanmax(pixel_slope(w, null_tilt=False))), 3), round(float(np.nanmax(pixel_slope(w))), 3)
    (0.5, 0.2)
    """
    values = np.asarray(waves, dtype=np.float64)
    if null_tilt:
        values = values - centring_tilt(values, resolution=1e-12).plane(values.shape)
    out = np.full(values.shape, np.nan)
    across = np.abs(np.diff(values, axis=1))
    down = np.abs(np.diff(values, axis=0))
    out[:, :-1] = np.fmax(out[:, :-1], across)
    out[:-1, :] = np.fmax(out[:-1, :], down)
    return out


def fringe_slope_bound(model: WavefrontModel, fields: Sequence[tuple[float, float]],
                       ranges: NDArray[np.floating], *, null_tilt: bool = True) -> float:
    """The first-order bound on the fringe slope over ``+-ranges`` (module notes), waves per pixel.

    Parameters
    ----------
    model : callable
        ``model(field_deg, pose) -> waves (H, W)``: the design telescope.
    fields : sequence of (float, float)
        Field points, deg.
    ranges : array (5,)
        The misalignment range per degree of freedom (X Y Z mm, U V deg), >= 0.
    null_tilt : bool
        Whether the interferometer's reference removes the tilt at each field point.

    Returns
    -------
    float
        The bound; compare with :data:`NYQUIST_WAVES_PER_PX`.
    """
    ranges = np.asarray(ranges, dtype=np.float64)
    if ranges.shape != (len(DOFS),) or not np.all(np.isfinite(ranges)) or np.any(ranges < 0):
        raise ValueError(f"ranges: expected {len(DOFS)} finite values >= 0 ({' '.join(DOFS)}), got {ranges}")
    worst = 0.0
    for field in fields:
        bound = pixel_slope(model(tuple(field), HexapodPose()), null_tilt)  # type: ignore[arg-type]
        for k, r in enumerate(ranges):
            if r == 0.0:
                continue
            state = np.zeros(6)
            state[k] = r
            plus = model(tuple(field), HexapodPose(*state))  # type: ignore[arg-type]
            minus = model(tuple(field), HexapodPose(*-state))  # type: ignore[arg-type]
            bound = bound + pixel_slope((plus - minus) / 2, null_tilt)
        worst = max(worst, float(np.nanmax(bound)))
    return worst
