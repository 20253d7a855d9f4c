"""The aperture options of ``wavestack analyze`` and the ``aperture`` object of its report.

``--aperture detected`` (default) analyses the aperture as detected from the modulation (any
shape); ``--aperture circle`` the circle fitted to the detected edge with outlier rejection (for
optics known to be round); ``--mask FILE`` the user's mask. The report gives the circle fitted to
the detected edge, centre and radius with their standard uncertainties in pixels, whichever
aperture is analysed.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from wavestack.pipeline import APERTURE_CHOICES, InputError, InterferometerOutcome, load_mask


def add_aperture_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare ``--aperture`` and ``--mask``."""
    parser.add_argument("--aperture", choices=APERTURE_CHOICES, default="detected",
                        help="detected: the aperture found in the modulation, any shape (default); "
                             "circle: the circle fitted to its edge, for optics known to be round")
    parser.add_argument("--mask", metavar="FILE",
                        help="analyse this mask instead (.npy or image, non-zero = valid, the frames' size)")


def aperture_mask(args: argparse.Namespace, shape: tuple[int, int]) -> np.ndarray | None:
    """The loaded ``--mask`` (None without one: ``--aperture`` names the choice).

    Raises
    ------
    InputError
        If both ``--mask`` and ``--aperture circle`` are given, or the mask file is unreadable,
        of another shape than the frames, or has no valid pixel.
    """
    if args.mask is None:
        return None
    if args.aperture != "detected":
        raise InputError(f"{args.mask}: --mask and --aperture {args.aperture} exclude each other; give one")
    mask = load_mask(args.mask, shape=shape)
    if not mask.any():
        raise InputError(f"{args.mask}: the mask has no valid pixel")
    return mask


def refuse_for_measured_map(args: argparse.Namespace, path: object) -> None:
    """A measured map's file says which pixels are valid: the aperture options do not apply.

    Raises
    ------
    InputError
        If ``--aperture circle`` or ``--mask`` is given with a ``.dat``/``.datx`` file.
    """
    if args.mask is not None or args.aperture != "detected":
        raise InputError(f"{path}: --aperture and --mask apply to interferograms; "
                         "a measured map's file says which pixels are valid")


def aperture_report(outcome: InterferometerOutcome) -> dict[str, Any]:
    """The JSON ``aperture`` object (centre and radius in pixels, column then row)."""
    aperture = outcome.aperture
    assert aperture is not None
    cx, cy, radius = aperture.enclosing_circle()
    rows, cols = np.nonzero(aperture.mask)
    report: dict[str, Any] = {
        "choice": outcome.aperture_choice,
        "centre": [cx, cy], "radius": radius,
        "bbox": [int(cols.min()), int(rows.min()), int(cols.max()), int(rows.max())],
        "topology": aperture.topology.value, "valid_pixels": int(aperture.valid_count),
    }
    edge = outcome.edge
    if edge is not None:
        report["edge_circle"] = {
            "centre": [edge.cx, edge.cy], "radius": edge.radius,
            "centre_uncertainty": [edge.sigma_cx, edge.sigma_cy], "radius_uncertainty": edge.sigma_radius,
            "rms_residual_px": edge.rms_residual_px, "points": edge.points, "rejected": edge.rejected,
        }
    return report


def format_aperture(ap: dict[str, Any]) -> str:
    """The human line(s) for the aperture."""
    line = (f"aperture    {ap['choice']}, {ap['topology']}, {ap['valid_pixels']} px, centre (col {ap['centre'][0]:.1f}, "
            f"row {ap['centre'][1]:.1f}), radius {ap['radius']:.1f} px")
    edge = ap.get("edge_circle")
    if edge is None:
        return line
    (cx, cy), (sx, sy) = edge["centre"], edge["centre_uncertainty"]
    return (line + f"\nedge        circle centre (col {cx:.2f} +- {sx:.2f}, row {cy:.2f} +- {sy:.2f}), "
            f"radius {edge['radius']:.2f} +- {edge['radius_uncertainty']:.2f} px "
            f"({edge['points']} edge points, {edge['rejected']} rejected)")
