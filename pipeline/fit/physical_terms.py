"""Physical piston, tilt and power: least squares in pixel coordinates, independent of any basis.

Interferometer software offers "remove PTT" and "remove power" as a fit of a plane (and a
paraboloid of revolution) to the measured map in the instrument's own coordinates, whatever
polynomial set is fitted afterwards. On a non-circular aperture these are *not* the Zernike
piston, tilt and defocus coefficients, which couple to higher terms; this module gives the
physical quantities.

Coordinates follow the project convention: pixel centres at integer (row, col); physical
x = col - cx and y = -(row - cy), so y points up. Lengths are normalised by a radius in pixels
(the pupil radius when a fitter is used) so that each term is reported as its value at that
radius: ``tilt_x`` is the height the plane reaches at x = +radius, ``power`` the height of the
paraboloid at the radius. Units are the units of the map.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

PhysicalRemoval = Literal["ptt", "pttp"]

_TERM_NAMES: dict[str, tuple[str, ...]] = {
    "ptt": ("piston", "tilt_x", "tilt_y"),
    "pttp": ("piston", "tilt_x", "tilt_y", "power"),
}


def physical_term_names(terms: str) -> tuple[str, ...]:
    """Names of the columns of :func:`physical_term_basis` for ``terms`` ("ptt" or "pttp").

    Raises
    ------
    ValueError
        If ``terms`` is not "ptt" or "pttp".
    """
    try:
        return _TERM_NAMES[terms]
    except KeyError:
        raise ValueError(f"terms: expected 'ptt' or 'pttp', got {terms!r}") from None


@dataclass(frozen=True)
class PhysicalTerms:
    """Piston, tilt and power fitted in physical coordinates.

    Attributes
    ----------
    piston : float
        Mean level, in map units.
    tilt_x, tilt_y : float
        Height of the fitted plane at x = +radius (y = +radius), in map units; y points up.
    power : float or None
        Height of the fitted paraboloid ``power * (x^2 + y^2) / radius^2`` at the radius, in map
        units; None when only piston and tilt were fitted.
    centre : tuple of float
        (cx, cy) origin of the coordinates in pixels (cx a column, cy a row coordinate).
    radius_px : float
        Normalising radius in pixels.
    """

    piston: float
    tilt_x: float
    tilt_y: float
    power: float | None
    centre: tuple[float, float]
    radius_px: float

    def as_dict(self) -> dict[str, object]:
        """A JSON-ready dictionary of the fitted terms and their coordinate frame."""
        return {
            "piston": self.piston,
            "tilt_x": self.tilt_x,
            "tilt_y": self.tilt_y,
            "power": self.power,
            "centre": list(self.centre),
            "radius_px": self.radius_px,
        }


def physical_term_basis(
    x: NDArray[np.float64], y: NDArray[np.float64], terms: str
) -> NDArray[np.float64]:
    """Design matrix of the physical terms at normalised coordinates.

    Parameters
    ----------
    x, y : ndarray, shape (N,)
        Coordinates divided by the normalising radius (x right, y up).
    terms : {"ptt", "pttp"}
        Piston and tilt, or piston, tilt and power.

    Returns
    -------
    ndarray, shape (N, 3) or (N, 4)
        Columns ``1, x, y`` and, for "pttp", ``x^2 + y^2``.
    """
    names = physical_term_names(terms)
    columns = [np.ones_like(x), x, y]
    if "power" in names:
        columns.append(x * x + y * y)
    return np.column_stack(columns)


def terms_from_vector(
    values: NDArray[np.float64], terms: str, centre: tuple[float, float], radius_px: float
) -> PhysicalTerms:
    """Wrap the least-squares solution vector of :func:`physical_term_basis` columns."""
    names = physical_term_names(terms)
    return PhysicalTerms(
        piston=float(values[0]),
        tilt_x=float(values[1]),
        tilt_y=float(values[2]),
        power=float(values[3]) if "power" in names else None,
        centre=(float(centre[0]), float(centre[1])),
        radius_px=float(radius_px),
    )


def remove_physical_terms(
    frame: NDArray[np.floating],
    mask: NDArray[np.bool_] | None = None,
    terms: str = "ptt",
    *,
    centre: tuple[float, float] | None = None,
    radius_px: float | None = None,
) -> tuple[NDArray[np.float64], PhysicalTerms]:
    """Fit and subtract piston, tilt (and power) from a map, like interferometer software.

    Parameters
    ----------
    frame : ndarray, shape (rows, cols)
        The map, in any units; values outside ``mask`` are ignored.
    mask : ndarray of bool, shape (rows, cols), optional
        Valid pixels; default: the finite pixels of ``frame``.
    terms : {"ptt", "pttp"}
        Which terms to remove.
    centre : (cx, cy), optional
        Coordinate origin in pixels (cx a column, cy a row coordinate); default: the centroid of
        the valid pixels.
    radius_px : float, optional
        Normalising radius in pixels; default: the largest distance of a valid pixel centre from
        the centre (1 for a single pixel).

    Returns
    -------
    residual : ndarray, shape (rows, cols)
        ``frame`` minus the fitted terms, NaN outside the mask.
    fitted : PhysicalTerms
        The removed terms.

    Raises
    ------
    ValueError
        If the shapes disagree, the mask has too few valid pixels for the terms, or a valid
        pixel is not finite.
    """
    frame = np.asarray(frame, dtype=np.float64)
    if frame.ndim != 2:
        raise ValueError(f"frame: expected a 2-D map, got shape {frame.shape}")
    mask = np.isfinite(frame) if mask is None else np.asarray(mask, dtype=bool)
    if mask.shape != frame.shape:
        raise ValueError(f"mask: expected shape {frame.shape} like the frame, got {mask.shape}")
    rows, cols = np.nonzero(mask)
    values = frame[rows, cols]
    if not np.all(np.isfinite(values)):
        raise ValueError("frame: NaN or infinity inside the mask; expected finite valid pixels")
    names = physical_term_names(terms)
    if rows.size < len(names):
        raise ValueError(f"mask: {rows.size} valid pixels cannot determine {len(names)} terms")
    if centre is None:
        centre = (float(cols.mean()), float(rows.mean()))
    x = cols - centre[0]
    y = centre[1] - rows
    if radius_px is None:
        radius_px = float(np.sqrt(np.max(x * x + y * y))) or 1.0
    basis = physical_term_basis(x / radius_px, y / radius_px, terms)
    solution, *_ = np.linalg.lstsq(basis, values, rcond=None)
    residual = np.full(frame.shape, np.nan)
    residual[rows, cols] = values - basis @ solution
    return residual, terms_from_vector(solution, terms, centre, radius_px)
