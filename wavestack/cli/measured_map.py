"""Measured maps on the command line: the file's own pixels, counted, and fit errors with advice.

A measured map (Zygo ``.dat``/``.datx``, 4D ``.h5``) says which pixels hold a measurement. The
fit uses exactly those pixels: nothing is filled, nothing is cut. An outline is still derived
(the detected aperture of the valid pixels, with its drop-outs filled, joined with every valid
pixel) for the pupil circle and for a mapped method's map, and the pixels inside that outline
without a measurement are reported as drop-outs.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from wavestack.cli.arguments import obscuration_ratio
from wavestack.pipeline import Aperture, DetectionSettings, FitBasis, FitterDiagnostics, IllConditionedBasis, InputError
from wavestack.pipeline import detect_aperture, read_measured_map, unsupported_reason

# How a fitting library's setting is spelled on each command line.
ANALYZE_FLAGS = {"method": "--fit-method", "modes": "--modes"}
FIT_FLAGS = {"method": "--method", "modes": "--modes"}


@dataclass(frozen=True, eq=False)
class MapWavefront:
    """A measured map in waves on its outline.

    Attributes
    ----------
    waves : ndarray, shape (rows, cols)
        Waves, NaN wherever the file has no measurement.
    aperture : Aperture
        The outline (module notes).
    valid : ndarray of bool
        The pixels holding a measurement.
    """

    waves: np.ndarray
    aperture: Aperture
    valid: np.ndarray


@dataclass(frozen=True)
class MapPixels:
    """Pixel counts of a measured map.

    Attributes
    ----------
    measured : int
        Pixels the file holds a measurement for.
    dropouts : int
        Pixels inside the aperture outline without a measurement (not fitted).
    outside_outline : int
        Measured pixels the outline detection alone would have cut (isolated pixels, rim
        spurs); they are fitted and inside the reported aperture.
    pitch_mm : float or None
        The file's pixel pitch (lateral resolution), mm; None when it does not say.
    """

    measured: int
    dropouts: int
    outside_outline: int
    pitch_mm: float | None = None

    def as_dict(self, fitted: int) -> dict[str, int]:
        """JSON form, with the count of pixels that entered the fit."""
        return {"measured": self.measured, "fitted": int(fitted), "dropouts_inside_aperture": self.dropouts,
                "outside_detected_outline": self.outside_outline}


def reject_unsupported(paths: Sequence[Path]) -> None:
    """Raise the "not supported" message for the first file wavestack cannot read.

    Raises
    ------
    InputError
        Naming the file, its kind and the kinds that are supported.
    """
    for path in paths:
        reason = unsupported_reason(path)
        if reason is not None:
            raise InputError(reason)


def read_map_wavefront(path: Path, wavelength_nm: float | None) -> tuple[MapWavefront, float, MapPixels]:
    """A measured map as waves on its outline aperture, NaN wherever the file has no measurement.

    Parameters
    ----------
    path : Path
        A ``.dat``, ``.datx`` or 4D ``.h5`` file.
    wavelength_nm : float, optional
        Overrides the file's wavelength.

    Returns
    -------
    (MapWavefront, float, MapPixels)
        The wavefront, the wavelength used in nanometres, the pixel counts.

    Raises
    ------
    InputError
        If the file cannot be read or gives no wavelength and none is given.
    """
    data = read_measured_map(path)
    wavelength = wavelength_nm or data.wavelength_nm
    if wavelength is None:
        raise InputError(f"{path}: the file gives no wavelength; expected --wavelength-nm")
    valid = np.asarray(data.valid)
    # the outline: the detected aperture (drop-outs filled) joined with every measured pixel
    settings = DetectionSettings(threshold=0.5)
    detected = detect_aperture(valid.astype(np.float64), settings).aperture.mask
    outline = detected | valid
    pixels = MapPixels(
        measured=int(valid.sum()),
        dropouts=int(np.count_nonzero(outline & ~valid)),
        outside_outline=int(np.count_nonzero(valid & ~detected)),
        pitch_mm=data.pixel_size_m * 1e3 if data.pixel_size_m and data.pixel_size_m > 0 else None,
    )
    waves = np.where(valid, data.map_nm / wavelength, np.nan)
    # a hole the join leaves (a drop-out next to the edge, which the opening cut open) is a drop-out too:
    # holes count as obscurations from the detection's own drop-out size on
    aperture = Aperture.from_mask(outline, min_hole_area_px=settings.fill_dropouts_below_px)
    return MapWavefront(waves, aperture, valid), wavelength, pixels


def advised(error: IllConditionedBasis, source: str, flags: dict[str, str]) -> InputError:
    """The fit failure as a one-line input error whose advice names this command's options.

    Parameters
    ----------
    error : IllConditionedBasis
        Its ``advice`` holds only remedies the library checked to work on this aperture.
    source : str
        The input, named first.
    flags : dict
        Library setting -> option of this command (``ANALYZE_FLAGS`` or ``FIT_FLAGS``).
    """
    options = [f"{flags[name]} {value}" for name, value in error.advice if name in flags]
    suffix = f" (on this command line: {' or '.join(options)})" if options else ""
    return InputError(f"{source}: {error}{suffix}")


def map_report(report: dict[str, Any], pixels: MapPixels | None, fitted: int) -> None:
    """Add the pixel counts of a measured map to an ``analyze`` report (in place)."""
    if pixels is None:
        return
    report["pixels"] = pixels.as_dict(fitted)
    report["aperture"]["valid_pixels"] = pixels.measured  # measured, never filled


def map_lines(report: dict[str, Any]) -> list[str]:
    """The text lines of the pixel counts and the fit method's choice."""
    lines = []
    if "pixels" in report:
        p = report["pixels"]
        lines.append(f"pixels      {p['measured']} measured, {p['fitted']} fitted, "
                     f"{p['dropouts_inside_aperture']} drop-outs inside the aperture (not fitted)")
    if report.get("fit_method_reason"):
        lines.append(f"fit method  {report['fit_method']}: {report['fit_method_reason']}")
    return lines + obscuration_lines(report)


def add_fit_method_argument(parser: argparse.ArgumentParser, flag: str, methods: Sequence[str]) -> None:
    """The fit-method option, ``auto`` by default."""
    parser.add_argument(flag, choices=tuple(methods), default="auto",
                        help="auto (default): circle where the circle basis is well conditioned on the "
                             "aperture, else csf-qcm; says which and why; annulus: annular Zernike terms "
                             "over the pupil annulus")
    parser.add_argument("--obscuration", type=obscuration_ratio, metavar="E",
                        help="annulus only: inner over outer radius, 0 < E < 1 (default: measured, the largest "
                             "circle about the pupil centre holding no valid pixel)")


def obscuration_report(basis: FitBasis, diagnostics: FitterDiagnostics) -> dict[str, Any]:
    """The report keys of annular terms: their obscuration ratio (and for ``annulus`` its source); {} otherwise."""
    if basis.annular_obscuration is None:
        return {}
    return {"annular_obscuration": basis.annular_obscuration, "obscuration_source": diagnostics.obscuration_source}


def obscuration_lines(report: dict[str, Any]) -> list[str]:
    """The text line of :func:`obscuration_report`'s keys, if any."""
    if report.get("annular_obscuration") is None:
        return []
    source = report.get("obscuration_source")
    how = {"given": " (given)", "measured": " (measured: the largest circle about the pupil centre free of "
                                            "valid pixels)"}.get(source or "", " (the map's annulus)")
    return [f"annulus     annular Zernike terms, unit RMS over obscuration {report['annular_obscuration']:.4f}{how}"]
