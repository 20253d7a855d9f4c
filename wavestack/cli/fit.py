"""``wavestack fit``: fit Zernike terms to one wavefront map and report them."""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from wavestack.cli.arguments import bounded_int
from wavestack.cli.command import Command
from wavestack.cli.example import synthetic_example
from wavestack.cli.measured_map import FIT_FLAGS, add_fit_method_argument, advised, obscuration_lines
from wavestack.cli.measured_map import obscuration_report
from wavestack.cli.outputs import check_output_file, json_text, require_finite, save_npy
from wavestack.cli.surface_options import add_surface_arguments, measure_surface, surface_lines, surface_request
from wavestack.cli.surface_options import wants_surface
from wavestack.figures import FitView, write_fit_figure
from wavestack.pipeline import (
    Aperture,
    FitResult,
    Fitter,
    IllConditionedBasis,
    InputError,
    Pupil,
    available_methods,
    build_fitter,
    SurfaceFigures,
    load_map,
    load_mask,
    read_measured_map,
)
from wavestack.pipeline.formats import MEASURED_MAP_SUFFIXES
from wavestack.pipeline import mode_name
from wavestack.pipeline.fit import AUTO_MAX_NOISE_GAIN, MAX_MODES
from wavestack.pipeline.mapping import MAX_TARGET_VERTICES

_DTYPES = {"float64": np.float64, "float32": np.float32}
# Above this coefficient noise amplification the human report warns that single coefficients
# mean little (100: 0.01 waves of pixel noise become ~1 wave of coefficient scatter at N/M ~ 1e4);
# the same level at which the `auto` method leaves the circle basis for a mapped one.
_NOISE_GAIN_WARNING = AUTO_MAX_NOISE_GAIN


MODES_ARGUMENT = bounded_int(MAX_MODES, "Noll 1000 reaches radial order 44")
MESH_VERTICES_ARGUMENT = bounded_int(MAX_TARGET_VERTICES, "a mesh finer than the pixels adds nothing")


def _pupil_argument(text: str) -> Pupil:
    parts = text.split(",")
    try:
        cx, cy, r = (float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected CX,CY,R in pixels (three numbers), got {text!r}"
        ) from None
    if not (np.isfinite([cx, cy, r]).all() and r > 0):
        raise argparse.ArgumentTypeError(f"expected finite CX,CY and R > 0 in pixels, got {text!r}")
    return Pupil(cx, cy, r)


def add_fit_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the options of ``wavestack fit``."""
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("wavefront", nargs="?",
                        help="2-D .npy map (NaN outside the aperture), or a .dat/.datx/4D .h5 map (nm)")
    source.add_argument(
        "--example", action="store_true", help="fit the bundled synthetic example instead"
    )
    parser.add_argument("--mask", help="mask (.npy or image, non-zero = valid); default: finite pixels")
    add_fit_method_argument(parser, "--method", available_methods())
    parser.add_argument("--modes", type=MODES_ARGUMENT, default=36, help=f"number of modes (36; at most {MAX_MODES})")
    parser.add_argument("--ordering", choices=("noll", "ansi", "fringe"), default="noll")
    parser.add_argument(
        "--pupil", type=_pupil_argument, help="unit disk CX,CY,R in pixels (CX column, CY row)"
    )
    parser.add_argument("--remove", choices=("ptt", "pttp"), help="remove piston/tilt(/power) first")
    parser.add_argument(
        "--laplacian", choices=("cotangent", "graph"), default="cotangent",
        help="interior weights of the csf-qcm map (graph: the paper's)",
    )
    parser.add_argument(
        "--mesh-vertices", type=MESH_VERTICES_ARGUMENT, default=15000,
        help=f"approximate mesh size of the mapped methods (15000; at most {MAX_TARGET_VERTICES})",
    )
    parser.add_argument(
        "--no-angular-balance", action="store_true",
        help="csf-qcm: the paper's map alone, without wavestack's angular area balancing",
    )
    parser.add_argument("--dtype", choices=tuple(_DTYPES), default="float64")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--save-fit", metavar="OUT.npy", help="save the fitted map (NaN outside)")
    parser.add_argument("--plot", metavar="OUT.png",
                        help="draw the measured, fitted and residual maps and the coefficients (PNG)")
    parser.add_argument("--map-unit", choices=("nm", "um"),
                        help="a .npy map's unit of surface height, for the surface figures (an instrument file "
                             "is in nm)")
    add_surface_arguments(parser)


@dataclass(frozen=True, eq=False)
class _Inputs:
    """What ``fit`` reads: the map, its mask, its name, the example's truth, its surface scale and pitch."""

    wavefront: np.ndarray
    mask: np.ndarray
    source: str
    truth: np.ndarray | None = None
    nm_per_unit: float | None = None  # None: the map's unit is not a known surface height
    pixel_mm: float | None = None


def _load_inputs(args: argparse.Namespace) -> _Inputs:
    if args.example:
        example = synthetic_example()
        return _Inputs(example.wavefront, example.mask, example.description, example.truth)
    pixel_mm = None
    if str(args.wavefront).lower().endswith(MEASURED_MAP_SUFFIXES):
        measured = read_measured_map(args.wavefront)
        wavefront, nm_per_unit = np.array(measured.map_nm), 1.0
        if measured.pixel_size_m and measured.pixel_size_m > 0:
            pixel_mm = measured.pixel_size_m * 1e3
    else:
        wavefront = load_map(args.wavefront)
        nm_per_unit = {"nm": 1.0, "um": 1e3, None: None}[args.map_unit]
    if args.mask:
        mask = load_mask(args.mask, shape=wavefront.shape)
        if not mask.any():
            raise InputError(f"{args.mask}: the mask has no valid pixel")
    else:
        mask = np.isfinite(wavefront)
    return _Inputs(wavefront, mask, args.wavefront, None, nm_per_unit, args.pixel_mm or pixel_mm)


def _surface_figures(args: argparse.Namespace, inputs: _Inputs) -> tuple[SurfaceFigures | None, dict[str, Any] | None]:
    """The surface figures of the map as given (before ``--remove``), when its unit is a known height."""
    if inputs.nm_per_unit is None:
        if wants_surface(args):
            what = "the bundled example is a wavefront in waves" if args.example else "a .npy map has no unit"
            raise InputError(f"the surface figures need a surface height map and {what}; "
                             "expected --map-unit nm or um (or an instrument file)")
        return None, None
    valid = inputs.mask & np.isfinite(inputs.wavefront)
    surface_nm = np.where(valid, inputs.wavefront * inputs.nm_per_unit, np.nan)
    return measure_surface(inputs.source, surface_nm, valid, surface_request(args), inputs.pixel_mm,
                           asked=wants_surface(args))


def run_fit(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Execute ``wavestack fit``; returns the exit status."""
    if args.example and args.mask:
        raise InputError("--mask cannot be combined with --example; expected one of them")
    save_to = check_output_file(args.save_fit, "--save-fit") if args.save_fit else None
    plot_to = check_output_file(args.plot, "--plot") if args.plot else None
    inputs = _load_inputs(args)
    wavefront, mask, source, truth = inputs.wavefront, inputs.mask, inputs.source, inputs.truth
    try:
        fitter = build_fitter(
            Aperture.from_mask(mask),
            method=args.method,
            modes=args.modes,
            ordering=args.ordering,
            pupil=args.pupil,
            dtype=_DTYPES[args.dtype],
            remove=args.remove,
            laplacian=args.laplacian,
            mesh_vertices=args.mesh_vertices,
            angular_balance=not args.no_angular_balance,
            obscuration=args.obscuration,
        )
    except IllConditionedBasis as error:
        raise advised(error, source, FIT_FLAGS) from None
    started = time.perf_counter()
    result = fitter.fit(wavefront, residual=True)
    fit_seconds = time.perf_counter() - started
    require_finite(source, "fit", [*result.coefficients, result.residual_rms, result.residual_pv])
    fitted = fitter.surface(result.coefficients)
    if save_to is not None:
        save_npy(save_to, fitted)
    truth_error = None
    if truth is not None:
        truth_view = truth if args.remove is None else truth - (wavefront - result.residual_map - fitted)
        truth_error = float(np.sqrt(np.nanmean((fitted - truth_view) ** 2)))
    report = fit_report(source, fitter, result, fit_seconds, truth_error)
    surface, surface_report = _surface_figures(args, inputs)
    if surface_report is not None:
        report["surface"] = surface_report
    if plot_to is not None:
        write_fit_figure(fit_view(source, _map_unit(args), fitter, result, surface), plot_to)
    if args.json:
        print(json_text(report))
    else:
        print(format_report(report))
    return 0


def _map_unit(args: argparse.Namespace) -> str:
    """The unit of the fitted map: waves (the example), nm (an instrument file), ``--map-unit`` or unknown (.npy)."""
    if args.example:
        return "waves"
    if str(args.wavefront).lower().endswith(".npy"):
        return args.map_unit or "map units"
    return "nm"


def fit_view(source: str, unit: str, fitter: Fitter, result: FitResult,
             surface: SurfaceFigures | None = None) -> FitView:
    """What ``--plot`` draws of a fit made with ``residual=True``: the map less removed terms, the fit, the
    residual, and the surface figures' PSD, slope and filtered panels when they were measured."""
    fitted = fitter.surface(result.coefficients)
    return FitView(measured=result.residual_map + fitted, fitted=fitted, residual=result.residual_map,
                   coefficients=result.coefficients, modes=tuple(fitter.basis.modes),
                   first_index=fitter.basis.first_index, unit=unit, source=source, method=fitter.basis.method,
                   removed=fitter.removal, surface=surface)


def fit_report(
    source: str,
    fitter: Fitter,
    result: FitResult,
    fit_seconds: float,
    truth_error_rms: float | None = None,
) -> dict[str, Any]:
    """The JSON object ``wavestack fit --json`` prints."""
    basis = result.basis
    diagnostics = fitter.diagnostics.as_dict()
    timings = dict(diagnostics.pop("timings"))
    timings["fit"] = fit_seconds
    report: dict[str, Any] = {
        "source": source,
        "method": basis.method,
        "method_reason": fitter.diagnostics.method_reason,
        "modes": len(basis.modes),
        "ordering": basis.ordering,
        "first_index": basis.first_index,
        "normalisation": basis.normalisation,
        "mode_indices": [list(nm) for nm in basis.modes],
        "coefficients": result.coefficients.tolist(),
        "residual_rms": result.residual_rms,
        "residual_pv": result.residual_pv,
        "valid_pixels": result.valid_count,
        "topology": fitter.aperture.topology.value,
        "pupil": basis.pupil.as_dict(),
        "dtype": fitter.dtype.name,
        "diagnostics": diagnostics,
        "timings": timings,
        **obscuration_report(basis, fitter.diagnostics),
    }
    if result.circle_coefficients is not None:
        report["circle_coefficients"] = result.circle_coefficients.tolist()
    if result.removed is not None:
        report["removed"] = result.removed.as_dict()
    if truth_error_rms is not None:
        report["truth_error_rms"] = truth_error_rms
    return report


def format_report(report: dict[str, Any]) -> str:
    """Human-readable form of :func:`fit_report`'s object."""
    pupil = report["pupil"]
    diagnostics = report["diagnostics"]
    lines = [
        f"source      {report['source']}",
        f"aperture    {report['topology']}, {report['valid_pixels']} valid pixels; pupil centre "
        f"(col {pupil['cx']:.2f}, row {pupil['cy']:.2f}), radius {pupil['radius']:.2f} px",
        f"fit         {report['method']}, {report['modes']} {report['ordering']} modes, "
        f"{report['normalisation']} normalisation, {report['dtype']}; "
        f"kappa(G) {diagnostics['gram_condition']:.4g}, noise gain {diagnostics['noise_gain']:.3g}",
        *([f"method      {report['method']}: {report['method_reason']}"] if report.get("method_reason") else []),
        f"timing      build {report['timings']['total'] * 1e3:.1f} ms, "
        f"fit {report['timings']['fit'] * 1e3:.2f} ms",
        f"residual    RMS {report['residual_rms']:.4g}, PV {report['residual_pv']:.4g} (map units)",
        *obscuration_lines(report),
    ]
    if diagnostics["noise_gain"] > _NOISE_GAIN_WARNING:
        lines.append(
            f"warning     noise gain {diagnostics['noise_gain']:.3g}: these modes are nearly "
            "degenerate on this aperture, so noise swamps the individual coefficients even where "
            "the fitted map is good; fit fewer modes or map the aperture (--method csf-qcm)"
        )
    if "truth_error_rms" in report:
        lines.append(f"truth       fitted map vs noise-free truth: RMS {report['truth_error_rms']:.3g}")
    if "removed" in report:
        removed = report["removed"]
        power = "" if removed["power"] is None else f", power {removed['power']:.4g}"
        lines.append(
            f"removed     piston {removed['piston']:.4g}, tilt x {removed['tilt_x']:.4g}, "
            f"tilt y {removed['tilt_y']:.4g}{power} (at radius {removed['radius_px']:.1f} px)"
        )
    if "surface" in report:
        lines += surface_lines(report["surface"])
    lines.append("")
    lines.append(f"{'j':>4}  {'(n, m)':>9}  {'name':<24} {'coefficient':>13}")
    for offset, ((n, m), value) in enumerate(zip(report["mode_indices"], report["coefficients"])):
        j = report["first_index"] + offset
        lines.append(f"{j:>4}  {f'({n}, {m})':>9}  {mode_name(n, m):<24} {value:>13.6g}")
    return "\n".join(lines)


COMMAND = Command(
    "fit",
    help="fit Zernike terms to a wavefront map (.npy, .dat, .datx, 4D .h5)",
    description="Fit Zernike terms to a 2-D wavefront map (.npy, NaN outside the aperture) or a measured map.",
    add_arguments=add_fit_arguments, handler=run_fit,
    subject=lambda args: "the bundled example" if args.example else str(args.wavefront),
)
