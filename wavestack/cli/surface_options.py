"""The surface figures on the command line (``analyze`` and ``fit``): options, the request, the report.

Every measured map gets the ISO 14999-4 form figures and PVr; the options add the drawing's
tolerance (``--spec``), the PSD (``--psd``, ``--psd-band-mm``), the RMS slope
(``--slope-length-mm``) and an areal filter (``--filter``). A value the command line cannot
read is refused by argparse in one line; a request the map's sampling cannot serve (a band
beyond its Nyquist frequency, an integration length under two pixels) is refused before the map
is measured, naming the option.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline import InputError, SurfaceAnalyzer, SurfaceFigures, SurfaceRequest, ToleranceError
from wavestack.pipeline import parse_areal_filter, parse_form_tolerance
from wavestack.pipeline.surface import ArealFilter, FormTolerance

__all__ = ["add_surface_arguments", "measure_surface", "surface_lines", "surface_request", "tolerance_argument",
           "wants_surface"]


def tolerance_argument(text: str) -> FormTolerance:
    """An argparse type: the drawing's tolerance, or the parser's one-line error with the reason."""
    try:
        return parse_form_tolerance(text)
    except ToleranceError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def _areal_filter(text: str) -> ArealFilter:
    try:
        return parse_areal_filter(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def _periods(text: str) -> tuple[float, float]:
    """Two spatial periods in mm, any order, as a band of frequencies (low, high) in cycles/mm."""
    try:
        periods = [float(v) for v in text.split(",")]
    except ValueError:
        periods = []
    if len(periods) != 2 or not all(np.isfinite(p) and p > 0 for p in periods) or periods[0] == periods[1]:
        raise argparse.ArgumentTypeError(f"expected two different spatial periods in mm, e.g. 0.5,10, got {text!r}")
    return 1.0 / max(periods), 1.0 / min(periods)


def _length(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (np.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected an integration length in mm > 0, got {text!r}")
    return value


def add_surface_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the surface-figure options."""
    group = parser.add_argument_group("surface figures (ISO 10110-5 / 14999-4, PVr, PSD, slope, filters)")
    group.add_argument("--spec", type=tolerance_argument, metavar="TOLERANCE",
                       help="the drawing's form tolerance, e.g. '3/2(0.5/0.2)' or '3/-(-/-; RMSi < 0.05)' "
                            "(fringes at 546.07 nm unless 'lambda = ... nm' follows): pass/fail per quantity")
    group.add_argument("--psd", action="store_true",
                       help="the PSD (2-D and azimuthally averaged), its band RMS and power law")
    group.add_argument("--psd-band-mm", type=_periods, metavar="P1,P2",
                       help="the band of the band-limited RMS and power-law fit, as two spatial periods in mm "
                            "(implies --psd; default: all the sampling resolves)")
    group.add_argument("--slope-length-mm", type=_length, metavar="L",
                       help="RMS slope (urad) over this integration length, mm (at least two pixels)")
    group.add_argument("--filter", type=_areal_filter, metavar="lp:LC|hp:LC|bp:LS,LC",
                       help="areal Gaussian filter, cut-off wavelengths in mm (50 %% at the cut-off): the "
                            "filtered surface's RMS and PV")
    group.add_argument("--pixel-mm", type=_length, metavar="P",
                       help="pixel pitch in mm, for the PSD, slope and filter when the input does not give it")


def wants_surface(args: argparse.Namespace) -> bool:
    """Whether any surface option was given."""
    return any(getattr(args, name) is not None for name in ("spec", "psd_band_mm", "slope_length_mm", "filter")) \
        or bool(args.psd)


def surface_request(args: argparse.Namespace) -> SurfaceRequest:
    """The request the options make."""
    return SurfaceRequest(tolerance=args.spec, psd=bool(args.psd) or args.psd_band_mm is not None,
                          band_per_mm=args.psd_band_mm, slope_length_mm=args.slope_length_mm,
                          areal_filter=args.filter)


def measure_surface(subject: str, surface_nm: NDArray[np.float64], valid: NDArray[np.bool_],
                    request: SurfaceRequest, pixel_mm: float | None, *,
                    asked: bool) -> tuple[SurfaceFigures | None, dict[str, Any]]:
    """The figures of one surface map and its ``surface`` report.

    A map too small for the figures (too few pixels for the form model or the 36-term PVr fit) is
    an error when surface options were given (``asked``), else the report says why there are
    none (``{"unavailable": reason}``): the rest of the command's report stands.

    Raises
    ------
    InputError
        For a request the map's sampling cannot serve (naming the option), or a map too small
        when ``asked``.
    """
    try:
        figures = SurfaceAnalyzer(valid, request, pixel_mm=pixel_mm).measure(surface_nm)
        return figures, figures.as_dict()
    except ValueError as error:
        text = str(error)
        for option, words in (("--psd-band-mm", "PSD band"), ("--slope-length-mm", "slope integration"),
                              ("--filter", "filter "), ("--pixel-mm", "pixel size")):
            if text.startswith(words):
                raise InputError(f"{subject}: {option}: {text}") from None
        if asked:
            raise InputError(f"{subject}: surface figures: {text}") from None
        return None, {"unavailable": text}


def surface_lines(report: dict[str, Any]) -> list[str]:
    """Text lines of a ``surface`` report object."""
    if "unavailable" in report:
        return [f"surface     no figures: {report['unavailable']}"]
    form = report["form"]
    fringes, nm = form["fringes"], form["nm"]
    lines = [
        f"form        SAG {fringes['SAG']:+.3f}, IRR {fringes['IRR']:.3f}, RSI {fringes['RSI']:.3f}, RMSt "
        f"{fringes['RMSt']:.3f}, RMSi {fringes['RMSi']:.3f}, RMSa {fringes['RMSa']:.3f} fringes at "
        f"{form['wavelength_nm']:g} nm (ISO 14999-4)",
        f"            PV {nm['PV']:.2f} nm, PVr {report['pvr']['nm']:.2f} nm (Evans: fit PV "
        f"{report['pvr']['fit_pv_nm']:.2f} + 3 x residual RMS {report['pvr']['residual_rms_nm']:.2f})",
    ]
    if "spec" in report:
        spec = report["spec"]
        verdict = "PASS" if spec["passed"] else "FAIL"
        lines.append(f"spec        {spec['notation']}: {verdict} (limiting {spec['limiting']}), fringes at "
                     f"{spec['wavelength_nm']:g} nm")
        lines.append("            " + "; ".join(
            f"{c['quantity']} {c['measured_fringes']:.3g} {'<=' if c['passed'] else '>'} {c['limit_fringes']:.3g}"
            + ("" if c["passed"] else " FAIL") for c in spec["checks"]))
    if "psd" in report and "band_rms_nm" in report["psd"]:
        psd = report["psd"]
        low, high = psd["band_per_mm"]
        law = psd["power_law"]
        lines.append(f"psd         band {low:.4g}-{high:.4g} cycles/mm (periods {1 / high:.4g}-{1 / low:.4g} mm): "
                     f"RMS {psd['band_rms_nm']:.3f} nm; power law {law['amplitude_nm2_mm2']:.4g} nm^2 mm^2 "
                     f"f^{law['slope']:.3f}")
    if "slope" in report:
        slope = report["slope"]
        lines.append(f"slope       over {slope['integration_length_mm']:g} mm: RMS {slope['rms_urad']:.3f} urad "
                     f"(x {slope['rms_x_urad']:.3f}, y {slope['rms_y_urad']:.3f})")
    if "filtered" in report:
        filtered = report["filtered"]
        kind = {"lp": "low-pass", "hp": "high-pass", "bp": "band-pass"}[filtered["kind"]]
        cutoffs = "-".join(f"{c:g}" for c in filtered["cutoffs_mm"])
        lines.append(f"filter      {kind} {cutoffs} mm: RMS {filtered['rms_nm']:.3f} nm, PV {filtered['pv_nm']:.3f} nm")
    return lines
