"""``wavestack analyze``: interferograms or instrument files to Zernike terms.

Several image files are a phase-shifted set in stepping order; one image is analysed by the
carrier method; a ``.dat`` (Zygo MetroPro), ``.datx`` or 4D ``.h5`` file is a measured map, fitted on
exactly the pixels it marks valid (:mod:`wavestack.cli.measured_map`).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from wavestack.cli.analyze_aperture import add_aperture_arguments, aperture_choice, aperture_report
from wavestack.cli.analyze_aperture import format_aperture, refuse_for_measured_map
from wavestack.cli.analyze_sh import add_shack_hartmann_arguments, requested as shack_hartmann, run_shack_hartmann
from wavestack.cli.arguments import finite_float, positive_finite_float, wavelength_nm
from wavestack.cli.fit import MODES_ARGUMENT, fit_view
from wavestack.figures import write_fit_figure
from wavestack.cli.outputs import check_output_file, json_text, require_finite, save_npy
from wavestack.cli.surface_options import add_surface_arguments, measure_surface, surface_lines, surface_request
from wavestack.cli.surface_options import wants_surface
from wavestack.cli.command import Command
from wavestack.cli.measured_map import ANALYZE_FLAGS, MapPixels, add_fit_method_argument, advised, fit_mask_of
from wavestack.cli.measured_map import obscuration_report
from wavestack.cli.measured_map import map_lines, map_report, read_map_wavefront, reject_unsupported
from wavestack.pipeline import Aperture, IllConditionedBasis, InputError, SurfaceFigures, available_methods
from wavestack.pipeline import Pupil, build_fitter
from wavestack.pipeline import ConicTest, implied_conic_constant, null_wavefront_waves
from wavestack.pipeline import read_frame, read_frame_set
from wavestack.pipeline import MeasuredWavefront, wavefront_from_carrier, wavefront_from_phase_shifts
from wavestack.pipeline.formats import MEASURED_MAP_SUFFIXES
from wavestack.pipeline import mode_name


def _steps_argument(text: str) -> np.ndarray:
    try:
        values = np.array([float(v) for v in text.split(",")])
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected phase steps in degrees, e.g. 0,60,120, got {text!r}") from None
    if not np.isfinite(values).all():
        raise argparse.ArgumentTypeError(f"expected finite phase steps in degrees, e.g. 0,60,120, got {text!r}")
    return np.deg2rad(values)


def add_analyze_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the options of ``wavestack analyze``."""
    parser.add_argument("files", nargs="+", metavar="FILE", help="images (a phase-shifted set or one carrier frame), or one .dat/.datx/4D .h5")
    parser.add_argument("--method", choices=("psi", "aia", "pca", "carrier"),
                        help="psi: least squares with known steps; aia/pca: steps estimated from the data "
                             "(default: psi for several frames, carrier for one)")
    parser.add_argument("--steps", type=_steps_argument, help="phase steps in degrees (default: 360/N apart)")
    parser.add_argument("--direction", choices=("ccw", "cw"), default="ccw", help="phase-step direction (ccw)")
    parser.add_argument("--carrier-sign", type=int, choices=(1, -1), default=1,
                        help="sign of a single carrier frame's phase (+1 or -1, for the tilt direction)")
    parser.add_argument("--wavelength-nm", type=wavelength_nm,
                        help="test wavelength, 1 nm to 1 mm (required for images; files carry it)")
    parser.add_argument("--modes", type=MODES_ARGUMENT, default=36)
    parser.add_argument("--ordering", choices=("noll", "ansi", "fringe"), default="noll")
    add_fit_method_argument(parser, "--fit-method", [m for m in available_methods() if m != "conformal"])
    parser.add_argument("--remove", choices=("ptt", "pttp"), help="remove piston/tilt(/power) before reporting")
    parser.add_argument("--null-conic", type=finite_float, metavar="K",
                        help="subtract the wavefront a conic of constant K shows at its centre of curvature "
                             "(needs --roc-mm and --diameter-mm)")
    parser.add_argument("--roc-mm", type=positive_finite_float, help="mirror radius of curvature, mm (for the null and the implied conic)")
    parser.add_argument("--diameter-mm", type=positive_finite_float, help="diameter of the analysed aperture, mm")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--save-map", metavar="OUT.npy", help="save the analysed wavefront (waves, NaN outside)")
    parser.add_argument("--plot", metavar="OUT.png",
                        help="draw the measured, fitted and residual maps and the coefficients (PNG)")
    parser.add_argument("--surface-factor", type=positive_finite_float, default=0.5, metavar="F",
                        help="interferograms: surface height per wavefront for the surface figures (0.5: a "
                             "surface in reflection at normal incidence; a measured map is already surface)")
    add_aperture_arguments(parser)
    add_surface_arguments(parser)
    add_shack_hartmann_arguments(parser)


def _measure(args: argparse.Namespace) -> tuple[MeasuredWavefront, float, MapPixels | None]:
    paths = [Path(p) for p in args.files]
    reject_unsupported(paths)
    suffixes = {p.suffix.lower() for p in paths}
    if suffixes & set(MEASURED_MAP_SUFFIXES):
        if len(paths) != 1:
            raise InputError(f"{paths[0]}: a measured map (.dat/.datx/.h5) is analysed on its own; got {len(paths)} files")
        refuse_for_measured_map(args, paths[0])
        return read_map_wavefront(paths[0], args.wavelength_nm)
    if args.wavelength_nm is None:
        raise InputError(f"{paths[0]}: --wavelength-nm is required for interferogram images")
    if len(paths) == 1:
        if args.method not in (None, "carrier"):
            raise InputError(f"{paths[0]}: one frame can only be analysed by the carrier method; got --method {args.method}")
        frame = read_frame(paths[0])
        choice = aperture_choice(args, frame.shape[:2])
        return wavefront_from_carrier(frame, sign=args.carrier_sign, aperture=choice), args.wavelength_nm, None
    if args.method == "carrier":
        raise InputError(f"{paths[0]}: the carrier method takes one frame; got {len(paths)}")
    frames = read_frame_set(paths)
    if args.steps is not None and len(args.steps) != len(paths):
        raise InputError(f"{paths[0]}: --steps gives {len(args.steps)} steps for {len(paths)} frames")
    method = {"psi": "lsq", None: "lsq", "aia": "aia", "pca": "pca"}[args.method]
    measured = wavefront_from_phase_shifts(frames, method=method, steps_rad=args.steps, direction=args.direction,
                                           aperture=aperture_choice(args, frames.shape[1:3]))
    return measured, args.wavelength_nm, None


def _null_test(args: argparse.Namespace, wavelength_nm: float) -> ConicTest | None:
    if args.roc_mm is None and args.diameter_mm is None and args.null_conic is None:
        return None
    if args.roc_mm is None or args.diameter_mm is None:
        raise InputError("--null-conic and the implied conic need both --roc-mm and --diameter-mm")
    return ConicTest(args.roc_mm, args.diameter_mm, wavelength_nm)


def _apply_null_test(args: argparse.Namespace, test: ConicTest, aperture: Aperture, waves: np.ndarray,
                     report: dict[str, Any]) -> np.ndarray:
    """Record the implied conic and, with ``--null-conic``, subtract that conic's null wavefront (waves)."""
    # the implied conic reads Z11 of the raw map over the aperture's circle (Noll, unit RMS)
    circle = build_fitter(aperture, modes=max(args.modes, 11), dtype=np.float64)
    pupil = circle.basis.pupil
    raw_spherical = circle.fit(waves, nan_policy="omit").coefficients[10]
    report["implied_conic"] = implied_conic_constant(raw_spherical, test)
    report["measured_spherical_waves"] = raw_spherical
    if args.null_conic is None:
        return waves
    rows, cols = np.indices(waves.shape)
    rho = np.hypot(cols - pupil.cx, rows - pupil.cy) / pupil.radius
    report["null_conic"] = args.null_conic
    return waves - np.where(aperture.mask, null_wavefront_waves(np.minimum(rho, 1.0), test, args.null_conic), np.nan)


def run_analyze(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Execute ``wavestack analyze``; returns the exit status."""
    if shack_hartmann(args):
        return _spot_image(args)
    save_to = check_output_file(args.save_map, "--save-map") if args.save_map else None
    plot_to = check_output_file(args.plot, "--plot") if args.plot else None
    try:
        measured, wavelength_nm, pixels = _measure(args)
    except InputError:
        raise
    except ValueError as error:  # the data, not the file, is unusable: say which input
        raise InputError(f"{_subject(args)}: {error}") from None
    aperture: Aperture = measured.aperture
    waves = np.where(aperture.mask, measured.waves, np.nan)
    test = _null_test(args, wavelength_nm)
    timings = dict(measured.timings)
    report: dict[str, Any] = {"files": list(args.files), "method": measured.method}
    if measured.steps_rad is not None:
        report["steps_deg"] = np.rad2deg(measured.steps_rad).tolist()
        report["steps_estimated"] = measured.method in ("aia", "pca")
    if measured.carrier is not None:
        report["carrier_cycles_per_px"] = list(measured.carrier)
    tick = time.perf_counter()
    if test is not None:
        waves = _apply_null_test(args, test, aperture, waves, report)
    try:
        fitter = build_fitter(
            aperture, method=args.fit_method, modes=args.modes, ordering=args.ordering,
            dtype=np.float64, remove=args.remove, fallback="qr", fit_mask=fit_mask_of(measured),
            obscuration=args.obscuration,
        )
    except IllConditionedBasis as error:
        raise advised(error, args.files[0], ANALYZE_FLAGS) from None
    result = fitter.fit(waves, nan_policy="omit", residual=True)
    timings["fit"] = time.perf_counter() - tick
    require_finite(_subject(args), "fit", [*result.coefficients, result.residual_rms])
    analysed = result.residual_map + fitter.surface(result.coefficients)  # the map less removed terms
    if save_to is not None:
        save_npy(save_to, analysed)
    rms, pv = float(np.nanstd(analysed)), float(np.nanmax(analysed) - np.nanmin(analysed))
    report.update({
        "wavelength_nm": wavelength_nm,
        "aperture": aperture_report(measured),
        "fit_method": fitter.basis.method, "fit_method_reason": fitter.diagnostics.method_reason,
        "modes": len(fitter.basis.modes), "ordering": fitter.basis.ordering,
        "first_index": fitter.basis.first_index, "normalisation": fitter.basis.normalisation,
        "mode_indices": [list(m) for m in fitter.basis.modes],
        "coefficients_waves": result.coefficients.tolist(),
        "residual_rms_waves": result.residual_rms,
        "rms_waves": rms, "pv_waves": pv, "rms_nm": rms * wavelength_nm, "pv_nm": pv * wavelength_nm,
        "diagnostics": fitter.diagnostics.as_dict(),
        "timings": timings,
        **obscuration_report(fitter.basis, fitter.diagnostics),
    })
    if result.removed is not None:
        report["removed"] = result.removed.as_dict()
    map_report(report, pixels, result.valid_count)
    surface, report["surface"] = _surface_figures(args, measured, waves, wavelength_nm, pixels, fitter.basis.pupil)
    if plot_to is not None:
        write_fit_figure(fit_view(_subject(args), "waves", fitter, result, surface), plot_to)
    print(json_text(report) if args.json else _format(report))
    return 0


def _surface_figures(args: argparse.Namespace, measured: MeasuredWavefront, waves: np.ndarray, wavelength_nm: float,
                     pixels: MapPixels | None, pupil: Pupil) -> tuple[SurfaceFigures | None, dict[str, Any]]:
    """The surface figures of the analysed map: nm of surface on its measured pixels (before ``--remove``).

    A measured map's nanometres are already the instrument's surface; an interferogram's wavefront
    becomes surface by ``--surface-factor``. The pixel pitch is ``--pixel-mm``, else the file's,
    else ``--diameter-mm`` over the pupil's diameter in pixels.
    """
    factor = 1.0 if measured.method == "file" else args.surface_factor
    valid = np.isfinite(waves) & measured.aperture.mask
    pixel_mm = args.pixel_mm
    if pixel_mm is None and pixels is not None:
        pixel_mm = pixels.pitch_mm
    if pixel_mm is None and args.diameter_mm is not None:
        pixel_mm = args.diameter_mm / (2.0 * pupil.radius)
    surface_nm = np.where(valid, waves * wavelength_nm * factor, np.nan)
    return measure_surface(_subject(args), surface_nm, valid, surface_request(args), pixel_mm,
                           asked=wants_surface(args))


def _spot_image(args: argparse.Namespace) -> int:
    """A Shack-Hartmann spot image, once the interferogram-only options are known to be absent."""
    if args.mask is not None or args.aperture != "detected":
        raise InputError(f"{args.files[0]}: --aperture and --mask apply to interferograms, not to a "
                         "Shack-Hartmann spot image (its pupil is --pupil-px)")
    if args.plot is not None:
        raise InputError(f"{args.files[0]}: --plot draws interferograms and measured maps, not a "
                         "Shack-Hartmann spot image; expected --plot without the Shack-Hartmann options")
    if wants_surface(args):
        raise InputError(f"{args.files[0]}: the surface figures (--spec, --psd, --slope-length-mm, --filter) apply to "
                         "interferograms and measured maps, not to a Shack-Hartmann spot image")
    return run_shack_hartmann(args)


def _subject(args: argparse.Namespace) -> str:
    """The input files, as error messages name them."""
    return args.files[0] if len(args.files) == 1 else f"{args.files[0]} (and {len(args.files) - 1} more)"


def _format(report: dict[str, Any]) -> str:
    ap = report["aperture"]
    lines = [
        f"files       {', '.join(report['files'])}",
        f"phase       {report['method']}"
        + (f", steps {', '.join(f'{s:.1f}' for s in report['steps_deg'])} deg"
           + (" (estimated)" if report.get("steps_estimated") else "") if "steps_deg" in report else ""),
        format_aperture(ap),
        f"wavefront   RMS {report['rms_waves']:.4f} waves ({report['rms_nm']:.1f} nm), "
        f"PV {report['pv_waves']:.4f} waves ({report['pv_nm']:.1f} nm) at {report['wavelength_nm']} nm",
    ]
    lines += map_lines(report)
    lines += surface_lines(report["surface"])
    if "implied_conic" in report:
        lines.append(f"conic       measured Z11 {report['measured_spherical_waves']:.4f} waves implies K = {report['implied_conic']:.3f}"
                     + (f"; null for K = {report['null_conic']} subtracted" if "null_conic" in report else ""))
    lines += ["", f"{'j':>4}  {'(n, m)':>9}  {'name':<24} {'waves':>10}"]
    for offset, ((n, m), value) in enumerate(zip(report["mode_indices"], report["coefficients_waves"])):
        lines.append(f"{report['first_index'] + offset:>4}  {f'({n}, {m})':>9}  {mode_name(n, m):<24} {value:>10.4f}")
    return "\n".join(lines)


COMMAND = Command(
    "analyze",
    help="interferograms (a phase-shifted set or one carrier frame) or a .dat/.datx file to Zernike terms",
    description="Analyse interferograms or instrument files: phase, aperture, unwrap, fit.",
    add_arguments=add_analyze_arguments, handler=run_analyze, subject=_subject,
)
