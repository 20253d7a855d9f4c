"""``wavestack analyze`` on a Shack-Hartmann spot image: the station's processor applied to a file.

One spot image goes through the one Shack-Hartmann signal path,
:class:`~wavestack.pipeline.instrument.ShackHartmannProcessor`, described either

* by a station file (``--config STATION.toml``): its ``[shack_hartmann]`` table exactly as the
  live station applies it (the processor :func:`~wavestack.station.build_processor` builds), so
  a frame recorded by ``wavestack run --record`` gives the same coefficients here; or
* by a reference image (``--reference``: a flat wavefront; the lattice, square or hexagonal, is
  found in it and the slopes are the spot displacements against its spots); or
* by the lenslet pitch (``--lenslet-pitch-um``: the lattice found in the image at that pitch,
  placed on its spots, so the mean spot displacement, the tilt, is not measured and reported as
  null; defocus shows as the spots' pitch against the described one).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from wavestack.cli.arguments import positive_finite_float
from wavestack.cli.outputs import json_text
from wavestack.config import ConfigError, load_station_config
from wavestack.pipeline import InputError, mode_list, mode_name, normalisation_factor, default_normalisation
from wavestack.pipeline import read_frame
from wavestack.pipeline.instrument import ShackHartmannProcessor, ShackHartmannSetup, SlopeOutcome
from wavestack.station import build_processor

_TILTS = ((1, -1), (1, 1))
#: The lit fraction of a spot image described on the command line: a real sensor's beam is rarely
#: even (a Gaussian beam leaves the outer lenslets at a fraction of the centre's light), while
#: 0.25 still drops a lenslet three quarters in the shadow. A station file sets its own.
LIT_FRACTION = 0.25


def add_shack_hartmann_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the Shack-Hartmann options of ``wavestack analyze``."""
    group = parser.add_argument_group("Shack-Hartmann spot images (one FILE; a station file, a reference or a "
                                      "lenslet pitch)")
    group.add_argument("--reference", metavar="REF", help="spot image of a flat wavefront: slopes are the spot "
                                                          "displacements against its spots")
    group.add_argument("--lenslet-pitch-um", type=positive_finite_float, metavar="P",
                       help="lenslet pitch, um: without --reference the lenslet centres are the lattice found "
                            "in FILE at this pitch (tilt is then not measured)")
    group.add_argument("--focal-length-mm", type=positive_finite_float, metavar="F", help="lenslet focal length, mm")
    group.add_argument("--pixel-um", type=positive_finite_float, metavar="S", help="camera pixel size, um")
    group.add_argument("--pupil-px", metavar="CX,CY,R", type=_pupil_argument,
                       help="Zernike disk in pixels (CX column, CY row); default: the disk the used lenslets cover")
    group.add_argument("--lit-fraction", type=_fraction_argument, metavar="F",
                       help=f"a lenslet counts when its spot holds this fraction of a typical full spot (the 90th "
                            f"percentile; default {LIT_FRACTION}: a beam's uneven illumination keeps its lenslets)")


def requested(args: argparse.Namespace) -> bool:
    """True when the options ask for Shack-Hartmann analysis: a sensor option, or ``--config`` of a Shack-Hartmann station.

    Raises
    ------
    InputError
        ``--config`` is not a valid station file.
    """
    if any(getattr(args, name, None) is not None
           for name in ("reference", "lenslet_pitch_um", "focal_length_mm", "pixel_um")):
        return True
    if getattr(args, "config", None) is None:
        return False
    try:
        return load_station_config(Path(args.config)).station.kind == "shack-hartmann"
    except ConfigError as error:
        raise InputError(str(error)) from None


def _pupil_argument(text: str) -> tuple[float, float, float]:
    try:
        cx, cy, radius = (float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected CX,CY,R in pixels (three numbers), got {text!r}") from None
    if not (np.isfinite([cx, cy, radius]).all() and radius > 0):
        raise argparse.ArgumentTypeError(f"expected finite CX,CY and R > 0, got {text!r}")
    return cx, cy, radius


def _fraction_argument(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a fraction in [0, 1], got {text!r}") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a fraction in [0, 1], got {text!r}")
    return value


def run_shack_hartmann(args: argparse.Namespace) -> int:
    """Execute ``wavestack analyze`` on a spot image; returns the exit status."""
    path = _check_options(args)
    frame = read_frame(path)
    reference = None
    if args.reference is not None:
        reference = read_frame(Path(args.reference))
        if reference.shape != frame.shape:
            raise InputError(f"{args.reference}: reference image of shape {reference.shape}; expected the spot "
                             f"image's shape {frame.shape}")
    processor = _processor(path, args, reference)
    outcome = processor.process([frame])
    if not outcome.valid:
        blamed = args.reference if outcome.reason.startswith("lattice:") and args.reference is not None else path
        raise InputError(f"{blamed}: {outcome.reason.split(': ', 1)[-1]}")
    report = _report(path, processor.setup, outcome, args)
    print(json_text(report) if args.json else _format(report))
    return 0


def _check_options(args: argparse.Namespace) -> Path:
    """The spot image's path, once every option a Shack-Hartmann analysis needs is there."""
    if len(args.files) != 1:
        raise InputError(f"{args.files[0]}: a Shack-Hartmann analysis takes one spot image; got {len(args.files)} "
                         f"files (the reference goes to --reference)")
    path = Path(args.files[0])
    if args.config is not None:
        described = [option for option, value in (("--reference", args.reference), ("--pupil-px", args.pupil_px),
                                                  ("--lenslet-pitch-um", args.lenslet_pitch_um),
                                                  ("--focal-length-mm", args.focal_length_mm),
                                                  ("--pixel-um", args.pixel_um),
                                                  ("--lit-fraction", args.lit_fraction)) if value is not None]
        if described:
            raise InputError(f"{path}: --config describes the sensor; {described[0]} cannot be combined with it")
        return path
    for option, value in (("--wavelength-nm", args.wavelength_nm), ("--focal-length-mm", args.focal_length_mm),
                          ("--pixel-um", args.pixel_um)):
        if value is None:
            raise InputError(f"{path}: {option} is required for a Shack-Hartmann spot image")
    if args.reference is None and args.lenslet_pitch_um is None:
        raise InputError(f"{path}: a Shack-Hartmann spot image needs --config STATION.toml, --reference REF or "
                         f"--lenslet-pitch-um")
    if not args.wavelength_nm > 0:
        raise InputError(f"{path}: --wavelength-nm must be > 0, got {args.wavelength_nm}")
    return path


def _processor(path: Path, args: argparse.Namespace, reference: np.ndarray | None) -> ShackHartmannProcessor:
    """The station's own processor (``--config``), or one for the lenslets the options describe."""
    if args.config is not None:
        processor = build_processor(load_station_config(args.config))
        assert isinstance(processor, ShackHartmannProcessor)  # requested() saw a Shack-Hartmann station
        return processor
    try:
        setup = ShackHartmannSetup(
            focal_length_um=args.focal_length_mm * 1e3, pixel_um=args.pixel_um, wavelength_nm=args.wavelength_nm,
            pitch_px=None if args.lenslet_pitch_um is None else args.lenslet_pitch_um / args.pixel_um,
            reference="ideal" if reference is None else "frame", pupil_px=args.pupil_px, modes=args.modes,
            ordering=args.ordering, lit_fraction=LIT_FRACTION if args.lit_fraction is None else args.lit_fraction)
    except ValueError as error:
        raise InputError(f"{path}: {error}") from None
    return ShackHartmannProcessor(setup, reference_frame=reference)


def _report(path: Path, setup: ShackHartmannSetup, outcome: SlopeOutcome, args: argparse.Namespace
            ) -> dict[str, Any]:
    assert outcome.coefficients_waves is not None and outcome.lenslets is not None and outcome.pupil_px is not None
    modes = mode_list(setup.ordering, setup.modes)
    reported = _reported(outcome.coefficients_waves, modes, args, outcome.tilt_measured)
    normalisation = default_normalisation(setup.ordering)
    factors = np.array([normalisation_factor(n, m, "rms") / normalisation_factor(n, m, normalisation)
                        for n, m in modes])
    waves = [None if value is None else float(value * factor) for value, factor in zip(reported, factors)]
    known = np.array([0.0 if value is None else value for value in reported])
    rms = float(np.sqrt(np.sum(known[1:] ** 2)))  # orthonormal unit-RMS terms: RMS over the disk
    lattice, lenslets = outcome.lenslets.lattice, outcome.lenslets
    misfit_waves = outcome.residual_rms / lattice.pitch_px  # the slope misfit, waves per pixel
    return {
        "files": [str(path)], "method": "shack-hartmann", "reference": args.reference, "config": args.config,
        "lattice": {"kind": lattice.kind, "pitch_px": lattice.pitch_px, "orientation_deg": lattice.orientation_deg,
                    "origin": list(lattice.origin_px), "lenslets": lattice.count},
        "used_lenslets": int(lenslets.lit.sum()), "pupil": list(outcome.pupil_px),
        "tilt_measured": outcome.tilt_measured, "wavelength_nm": setup.wavelength_nm, "modes": len(modes),
        "ordering": setup.ordering, "first_index": 0 if setup.ordering == "ansi" else 1,
        "normalisation": normalisation, "mode_indices": [list(mode) for mode in modes], "coefficients_waves": waves,
        "coefficients_nm": [None if w is None else w * setup.wavelength_nm for w in waves],
        "rms_waves": rms, "rms_nm": rms * setup.wavelength_nm,
        "slope_residual_rms_waves_per_px": misfit_waves, "residual_rms_waves": outcome.residual_rms,
        "residual_pv_waves": outcome.residual_pv,
        "condition": outcome.diagnostics.condition if outcome.diagnostics is not None else None,
    }


def _reported(coefficients: np.ndarray, modes: list[tuple[int, int]], args: argparse.Namespace,
              tilt_measured: bool) -> list[float | None]:
    """Unit-RMS coefficients as reported: None for tilt when not measured; removed terms 0."""
    removed = {"ptt": {(0, 0), *_TILTS}, "pttp": {(0, 0), *_TILTS, (2, 0)}}.get(args.remove or "", set())
    return [0.0 if mode in removed else None if (mode in _TILTS and not tilt_measured) else float(value)
            for mode, value in zip(modes, coefficients)]


def _format(report: dict[str, Any]) -> str:
    lattice = report["lattice"]
    cx, cy, radius = report["pupil"]
    lines = [
        f"file        {report['files'][0]}" + (f" against {report['reference']}" if report["reference"] else ""),
        f"lenslets    {lattice['kind']} lattice, pitch {lattice['pitch_px']:.3f} px at "
        f"{lattice['orientation_deg']:.2f} deg, {report['used_lenslets']} of {lattice['lenslets']} used",
        f"pupil       centre (col {cx:.1f}, row {cy:.1f}), radius {radius:.1f} px",
        f"wavefront   RMS {report['rms_waves']:.4f} waves ({report['rms_nm']:.1f} nm) at {report['wavelength_nm']} nm"
        + ("" if report["tilt_measured"] else ", tilt not measured (no reference)"),
        "", f"{'j':>4}  {'(n, m)':>9}  {'name':<24} {'waves':>10} {'nm':>10}",
    ]
    for offset, ((n, m), value) in enumerate(zip(report["mode_indices"], report["coefficients_waves"])):
        shown = f"{'-':>10} {'-':>10}" if value is None else f"{value:>10.4f} {value * report['wavelength_nm']:>10.2f}"
        lines.append(f"{report['first_index'] + offset:>4}  {f'({n}, {m})':>9}  {mode_name(n, m):<24} {shown}")
    return "\n".join(lines)
