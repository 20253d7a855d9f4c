"""``wavestack analyze``: interferograms or instrument files to Zernike terms.

Several image files are a phase-shifted set in stepping order; one image is analysed by the
carrier method. Either is measured by the one interferometer processor the station runs
(:func:`~wavestack.pipeline.measure_set`: a stream of one set), with analyze's own settings or a
station's (``--config``, :mod:`wavestack.cli.analyze_settings`). A ``.dat`` (Zygo MetroPro),
``.datx`` or 4D ``.h5`` file is a measured map, fitted on exactly the pixels it marks valid
(:mod:`wavestack.cli.measured_map`) by the same fit stage (:func:`~wavestack.pipeline.instrument.measure_map`).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from wavestack.cli.analyze_aperture import add_aperture_arguments, aperture_mask, aperture_report
from wavestack.cli.analyze_aperture import format_aperture, refuse_for_measured_map
from wavestack.cli.analyze_settings import analyze_settings, conic_test, station_config, steps_argument, with_defaults
from wavestack.cli.analyze_sh import add_shack_hartmann_arguments, requested as shack_hartmann, run_shack_hartmann
from wavestack.cli.arguments import finite_float, positive_finite_float, unit_fraction, wavelength_nm
from wavestack.cli.fit import MODES_ARGUMENT, fit_view
from wavestack.figures import write_fit_figure
from wavestack.cli.outputs import check_output_file, json_text, require_finite, save_npy
from wavestack.cli.surface_options import add_surface_arguments, measure_surface, surface_lines, surface_request
from wavestack.cli.surface_options import wants_surface
from wavestack.cli.command import Command
from wavestack.cli.measured_map import ANALYZE_FLAGS, MapPixels, add_fit_method_argument, advised
from wavestack.cli.measured_map import obscuration_report
from wavestack.cli.measured_map import map_lines, map_report, read_map_wavefront, reject_unsupported
from wavestack.pipeline import Aperture, IllConditionedBasis, InputError, Pupil, SurfaceFigures
from wavestack.pipeline import available_methods, build_fitter, implied_conic_constant
from wavestack.pipeline import read_frame, read_frame_set
from wavestack.pipeline.formats import MEASURED_MAP_SUFFIXES
from wavestack.pipeline import mode_name
from wavestack.pipeline.instrument import OUTSIDE, InterferometerOutcome, InterferometerSettings, measure_map
from wavestack.pipeline.instrument import measure_set, null_waves


def add_analyze_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the options of ``wavestack analyze``."""
    parser.add_argument("files", nargs="+", metavar="FILE", help="images (a phase-shifted set or one carrier frame), or one .dat/.datx/4D .h5")
    parser.add_argument("--config", metavar="STATION.toml",
                        help="measure the files as this station measures its frames (the numbers the station "
                             "gives): an interferometer's [processing], or a Shack-Hartmann station's "
                             "[shack_hartmann] for one spot image")
    parser.add_argument("--method", choices=("psi", "aia", "pca", "carrier"),
                        help="psi: least squares with known steps; aia/pca: steps estimated from the data "
                             "(default: psi for several frames, carrier for one)")
    parser.add_argument("--steps", type=steps_argument, help="phase steps in degrees (default: 360/N apart)")
    parser.add_argument("--direction", choices=("ccw", "cw"), help="phase-step direction (default ccw)")
    parser.add_argument("--carrier-sign", type=int, choices=(1, -1),
                        help="sign of a single carrier frame's phase (+1, the default, or -1, for the tilt direction)")
    parser.add_argument("--calibration", type=Path, metavar="CAL.h5",
                        help="subtract this reference calibration from the map (interferograms of its camera grid)")
    parser.add_argument("--wavelength-nm", type=wavelength_nm,
                        help="test wavelength, 1 nm to 1 mm (required for images without --config; files carry it)")
    parser.add_argument("--modes", type=MODES_ARGUMENT, help="Zernike terms fitted (default 36)")
    parser.add_argument("--ordering", choices=("noll", "ansi", "fringe"), help="mode ordering (default noll)")
    add_fit_method_argument(parser, "--fit-method", [m for m in available_methods() if m != "conformal"])
    parser.set_defaults(fit_method=None)
    parser.add_argument("--remove", choices=("ptt", "pttp"), help="remove piston/tilt(/power) before reporting")
    parser.add_argument("--min-modulation", type=unit_fraction, metavar="F",
                        help="leave out pixels below this fraction of the aperture's mean modulation (default 0.1)")
    parser.add_argument("--clip-sigma", type=positive_finite_float, metavar="S",
                        help="spike clipping: leave out pixels whose fit residual exceeds S residual RMS (default 6)")
    parser.add_argument("--no-clip", action="store_true", help="no spike clipping")
    parser.add_argument("--null-conic", type=finite_float, metavar="K",
                        help="subtract the wavefront a conic of constant K shows at its centre of curvature "
                             "(needs --roc-mm and --diameter-mm)")
    parser.add_argument("--roc-mm", type=positive_finite_float, help="mirror radius of curvature, mm (for the null and the implied conic)")
    parser.add_argument("--diameter-mm", type=positive_finite_float, help="diameter of the analysed aperture, mm")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--save-map", metavar="OUT.npy", help="save the analysed wavefront (waves, NaN outside and where left out)")
    parser.add_argument("--plot", metavar="OUT.png",
                        help="draw the measured, fitted and residual maps and the coefficients (PNG)")
    parser.add_argument("--surface-factor", type=positive_finite_float, default=0.5, metavar="F",
                        help="interferograms: surface height per wavefront for the surface figures (0.5: a "
                             "surface in reflection at normal incidence; a measured map is already surface)")
    add_aperture_arguments(parser)
    add_surface_arguments(parser)
    add_shack_hartmann_arguments(parser)


def _measure(args: argparse.Namespace) -> tuple[argparse.Namespace, InterferometerOutcome, float, MapPixels | None,
                                                InterferometerSettings]:
    """The files measured: (the options with their defaults, the outcome, the wavelength in nm, a map's pixel
    counts, the settings measured with)."""
    paths = [Path(p) for p in args.files]
    reject_unsupported(paths)
    if {p.suffix.lower() for p in paths} & set(MEASURED_MAP_SUFFIXES):
        if len(paths) != 1:
            raise InputError(f"{paths[0]}: a measured map (.dat/.datx/.h5) is analysed on its own; got {len(paths)} files")
        if args.config is not None:
            raise InputError(f"{paths[0]}: --config applies to interferograms; a measured map has no processing")
        if args.calibration is not None:
            raise InputError(f"{paths[0]}: --calibration applies to interferograms of the calibrated camera grid, "
                             "not to a measured map")
        refuse_for_measured_map(args, paths[0])
        args = with_defaults(args)
        measured, wavelength, pixels = read_map_wavefront(paths[0], args.wavelength_nm)
        settings = analyze_settings(args, 2, None, wavelength)
        try:
            outcome = measure_map(measured.waves, measured.aperture, measured.valid, settings)
        except IllConditionedBasis as error:
            raise advised(error, args.files[0], ANALYZE_FLAGS) from None
        return args, outcome, wavelength, pixels, settings
    config = station_config(args)
    if config is None:
        args = with_defaults(args)
    wavelength = args.wavelength_nm or (config.station.wavelength_nm if config is not None else None)
    if wavelength is None:
        raise InputError(f"{paths[0]}: --wavelength-nm is required for interferogram images (or give --config)")
    frames = [read_frame(paths[0])] if len(paths) == 1 else list(read_frame_set(paths))
    settings = analyze_settings(args, len(frames), config, wavelength)
    try:
        outcome = measure_set(frames, settings, mask=aperture_mask(args, frames[0].shape[:2]))
    except ValueError as error:  # a set of the wrong length for the station, frames of another shape
        raise InputError(f"{_subject(args)}: {error}") from None
    if not outcome.valid:
        if isinstance(outcome.error, IllConditionedBasis):
            raise advised(outcome.error, args.files[0], ANALYZE_FLAGS)
        raise InputError(f"{_subject(args)}: {outcome.reason}")
    return args, outcome, wavelength, None, settings


def _implied_conic(args: argparse.Namespace, outcome: InterferometerOutcome, wavelength_nm: float,
                   report: dict[str, Any]) -> None:
    """The conic the measured map's spherical term implies (Noll Z11 over the fit grid's circle), before any null."""
    if args.roc_mm is None and args.diameter_mm is None and args.null_conic is None:
        return
    test = conic_test(args, wavelength_nm)
    assert outcome.flags is not None and outcome.waves is not None
    circle = build_fitter(Aperture.from_mask(outcome.flags != OUTSIDE), modes=max(args.modes or 36, 11),
                          dtype=np.float64)
    raw_spherical = float(circle.fit(outcome.waves, nan_policy="omit").coefficients[10])
    report["implied_conic"] = implied_conic_constant(raw_spherical, test)
    report["measured_spherical_waves"] = raw_spherical
    if args.null_conic is not None:
        report["null_conic"] = args.null_conic


def run_analyze(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Execute ``wavestack analyze``; returns the exit status."""
    if shack_hartmann(args):
        return _spot_image(args)
    save_to = check_output_file(args.save_map, "--save-map") if args.save_map else None
    plot_to = check_output_file(args.plot, "--plot") if args.plot else None
    args, outcome, wavelength_nm, pixels, settings = _measure(args)
    fit, choice = outcome.fit, outcome.choice
    assert fit is not None and choice is not None and fit.residual_map is not None
    fitter = choice.fitter
    require_finite(_subject(args), "fit", [*fit.coefficients, fit.residual_rms])
    analysed = fit.residual_map + fitter.surface(fit.coefficients)  # the map less removed terms (and a null)
    if save_to is not None:
        save_npy(save_to, analysed)
    report = _report(args, outcome, wavelength_nm, float(np.nanstd(analysed)))
    _implied_conic(args, outcome, wavelength_nm, report)
    if outcome.calibration is not None:
        report["calibration_sha256"] = outcome.calibration
    map_report(report, pixels, fit.valid_count)
    surface, report["surface"] = _surface_figures(args, outcome, settings, wavelength_nm, pixels, fitter.basis.pupil)
    if plot_to is not None:
        write_fit_figure(fit_view(_subject(args), "waves", fitter, fit, surface), plot_to)
    print(json_text(report) if args.json else _format(report))
    return 0


def _report(args: argparse.Namespace, outcome: InterferometerOutcome, wavelength_nm: float,
            rms: float) -> dict[str, Any]:
    """The JSON object of an analysed outcome."""
    fit, fitter = outcome.fit, outcome.choice.fitter  # type: ignore[union-attr]
    assert fit is not None and outcome.quality is not None
    figures = outcome.statistics
    report: dict[str, Any] = {"files": list(args.files), "method": outcome.method}
    if args.config is not None:
        report["config"] = str(args.config)
    if outcome.steps_rad is not None:
        report["steps_deg"] = np.rad2deg(outcome.steps_rad).tolist()
        report["steps_estimated"] = outcome.method in ("aia", "pca")
    if outcome.carrier is not None:
        report["carrier_cycles_per_px"] = list(outcome.carrier)
    report.update({
        "wavelength_nm": wavelength_nm,
        "aperture": aperture_report(outcome),
        "fit_method": fitter.basis.method, "fit_method_reason": fitter.diagnostics.method_reason,
        "modes": len(fitter.basis.modes), "ordering": fitter.basis.ordering,
        "first_index": fitter.basis.first_index, "normalisation": fitter.basis.normalisation,
        "mode_indices": [list(m) for m in fitter.basis.modes],
        "coefficients_waves": fit.coefficients.tolist(),
        "residual_rms_waves": fit.residual_rms, "residual_pv_waves": figures.residual_pv,
        "rms_waves": rms, "pv_waves": figures.pv, "pvr_waves": figures.pvr,
        "rms_nm": rms * wavelength_nm, "pv_nm": figures.pv * wavelength_nm, "pvr_nm": figures.pvr * wavelength_nm,
        "quality": outcome.quality.to_json(),
        "diagnostics": fitter.diagnostics.as_dict(),
        "timings": dict(outcome.timings_s),
        **obscuration_report(fitter.basis, fitter.diagnostics),
    })
    if fit.removed is not None:
        report["removed"] = fit.removed.as_dict()
    return report


def _surface_figures(args: argparse.Namespace, outcome: InterferometerOutcome, settings: InterferometerSettings,
                     wavelength_nm: float, pixels: MapPixels | None,
                     pupil: Pupil) -> tuple[SurfaceFigures | None, dict[str, Any]]:
    """The surface figures of the analysed map: nm of surface on the pixels the fit used (before ``--remove``).

    The map is the fit's (less a null test's wavefront), on the fit grid. A measured map's
    nanometres are already the instrument's surface; an interferogram's wavefront becomes surface
    by ``--surface-factor``. The pixel pitch is ``--pixel-mm`` (a camera pixel; times the fit
    grid's decimation), else the file's, else ``--diameter-mm`` over the pupil's diameter in pixels.
    """
    assert outcome.waves is not None and outcome.flags is not None
    waves = outcome.waves
    if settings.null is not None:
        waves = waves - null_waves(Aperture.from_mask(outcome.flags != OUTSIDE), settings.null)
    factor = 1.0 if outcome.method == "file" else args.surface_factor
    valid = np.isfinite(waves)
    pixel_mm = None if args.pixel_mm is None else args.pixel_mm * settings.fit_decimation
    if pixel_mm is None and pixels is not None:
        pixel_mm = pixels.pitch_mm
    if pixel_mm is None and args.diameter_mm is not None:
        pixel_mm = args.diameter_mm / (2.0 * pupil.radius)
    surface_nm = np.where(valid, waves * wavelength_nm * factor, np.nan)
    return measure_surface(_subject(args), surface_nm, valid, surface_request(args), pixel_mm,
                           asked=wants_surface(args))


def _spot_image(args: argparse.Namespace) -> int:
    """A Shack-Hartmann spot image, once the interferogram-only options are known to be absent."""
    args = with_defaults(args)
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


def quality_text(quality: dict[str, int]) -> str:
    """The pixels used, and why the others inside the aperture were left out."""
    q = quality
    return (f"pixels      {q['used']} used of {q['inside']} inside the aperture; left out {q['excluded']}: "
            f"low modulation {q['low_modulation']}, saturated {q['saturated']}, fringe order "
            f"{q['untrusted_order']}, clipped {q['clipped']}, rim {q['rim']}")


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
        f"PV {report['pv_waves']:.4f} waves ({report['pv_nm']:.1f} nm), "
        f"PVr {report['pvr_waves']:.4f} waves ({report['pvr_nm']:.1f} nm) at {report['wavelength_nm']} nm",
        quality_text(report["quality"]),
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
