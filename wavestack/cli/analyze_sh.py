"""``wavestack analyze`` on a Shack-Hartmann spot image: lenslet lattice, spots, slopes, Zernike terms.

One spot image and either a reference image (a flat wavefront: the slopes are the spot
displacements against the reference's spots) or a lenslet description (pitch, focal length,
pixel size: the lenslet centres are the lattice found in the image, at the described pitch).
The lattice, square or hexagonal, is found from the spots
(:func:`~wavestack.pipeline.shack_hartmann.detect_lattice`); the spots are centroided in their
lenslet windows, turned into slopes (``displacement * pixel / focal length``) and into Zernike
terms by modal least squares over the pupil disk
(:class:`~wavestack.pipeline.shack_hartmann.ModalReconstructor`).

Without a reference the absolute lenslet positions on the camera are unknown: the lattice is
placed on the spots, so the mean spot displacement (the tilt) is not measured and tilt is
reported as null; defocus shows as the spots' pitch against the described one.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from wavestack.cli.arguments import positive_finite_float
from wavestack.cli.outputs import json_text
from wavestack.pipeline import InputError, mode_list, mode_name, normalisation_factor, default_normalisation
from wavestack.pipeline import read_frame
from wavestack.pipeline.shack_hartmann import (
    Centroider, LensletLattice, ModalReconstructor, SpotMeasurement, convert_slopes, detect_lattice, slopes,
)

_PITCH_AGREEMENT = 0.2  # the spots' pitch and the described one may differ by this fraction (defocus)
_LIT_FRACTION = 0.25  # a spot dimmer than this fraction of the median reference spot is not used
_TILTS = ((1, -1), (1, 1))


def add_shack_hartmann_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the Shack-Hartmann options of ``wavestack analyze``."""
    group = parser.add_argument_group("Shack-Hartmann spot images (one FILE; a reference or a lenslet pitch)")
    group.add_argument("--reference", metavar="REF", help="spot image of a flat wavefront: slopes are the spot "
                                                          "displacements against its spots")
    group.add_argument("--lenslet-pitch-um", type=positive_finite_float, metavar="P",
                       help="lenslet pitch, um: without --reference the lenslet centres are the lattice found "
                            "in FILE at this pitch (tilt is then not measured)")
    group.add_argument("--focal-length-mm", type=positive_finite_float, metavar="F", help="lenslet focal length, mm")
    group.add_argument("--pixel-um", type=positive_finite_float, metavar="S", help="camera pixel size, um")
    group.add_argument("--pupil-px", metavar="CX,CY,R", type=_pupil_argument,
                       help="Zernike disk in pixels (CX column, CY row); default: the disk the used lenslets cover")


def requested(args: argparse.Namespace) -> bool:
    """True when the options ask for Shack-Hartmann analysis."""
    return any(getattr(args, name, None) is not None
               for name in ("reference", "lenslet_pitch_um", "focal_length_mm", "pixel_um"))


def _pupil_argument(text: str) -> tuple[float, float, float]:
    try:
        cx, cy, radius = (float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected CX,CY,R in pixels (three numbers), got {text!r}") from None
    if not (np.isfinite([cx, cy, radius]).all() and radius > 0):
        raise argparse.ArgumentTypeError(f"expected finite CX,CY and R > 0, got {text!r}")
    return cx, cy, radius


def run_shack_hartmann(args: argparse.Namespace) -> int:
    """Execute ``wavestack analyze`` on a spot image; returns the exit status."""
    path = _check_options(args)
    frame = read_frame(path)
    if args.reference is not None:
        lattice, reference, spots = _against_reference(path, frame, args)
    else:
        lattice, reference, spots = _against_description(path, frame, args)
    report = _reconstruct(path, lattice, reference, spots, args)
    print(json_text(report) if args.json else _format(report))
    return 0


def _check_options(args: argparse.Namespace) -> Path:
    """The spot image's path, once every option a Shack-Hartmann analysis needs is there."""
    if len(args.files) != 1:
        raise InputError(f"{args.files[0]}: a Shack-Hartmann analysis takes one spot image; got {len(args.files)} "
                         f"files (the reference goes to --reference)")
    path = Path(args.files[0])
    for option, value in (("--wavelength-nm", args.wavelength_nm), ("--focal-length-mm", args.focal_length_mm),
                          ("--pixel-um", args.pixel_um)):
        if value is None:
            raise InputError(f"{path}: {option} is required for a Shack-Hartmann spot image")
    if args.reference is None and args.lenslet_pitch_um is None:
        raise InputError(f"{path}: a Shack-Hartmann spot image needs --reference REF or --lenslet-pitch-um")
    if not args.wavelength_nm > 0:
        raise InputError(f"{path}: --wavelength-nm must be > 0, got {args.wavelength_nm}")
    return path


def _lattice_of(path: Path, frame: np.ndarray) -> LensletLattice:
    try:
        return detect_lattice(frame)
    except ValueError as error:
        raise InputError(f"{path}: {str(error).removeprefix('frame: ')}") from None


def _against_reference(path: Path, frame: np.ndarray, args: argparse.Namespace
                       ) -> tuple[LensletLattice, SpotMeasurement, SpotMeasurement]:
    """The lattice of the reference image, its spots (the reference positions) and the image's spots."""
    reference_path = Path(args.reference)
    reference = read_frame(reference_path)
    if reference.shape != frame.shape:
        raise InputError(f"{reference_path}: reference image of shape {reference.shape}; expected the spot "
                         f"image's shape {frame.shape}")
    lattice = _lattice_of(reference_path, reference)
    if args.lenslet_pitch_um is not None:
        _check_pitch(reference_path, lattice, args)
    centroider = Centroider.build(lattice, frame.shape)
    return lattice, centroider.measure(reference), centroider.measure(frame)


def _against_description(path: Path, frame: np.ndarray, args: argparse.Namespace
                         ) -> tuple[LensletLattice, SpotMeasurement, SpotMeasurement]:
    """The lattice found in the image at the described pitch (origin on the spots), its centres, the spots."""
    found = _lattice_of(path, frame)
    _check_pitch(path, found, args)
    scale = args.lenslet_pitch_um / args.pixel_um / found.pitch_px
    basis = np.asarray(found.basis_px) * scale
    spots = Centroider.build(found, frame.shape).measure(frame)
    used = spots.valid
    # the origin that puts the described lattice on the spots in the least-squares sense (the mean tilt)
    origin = np.mean(spots.centroids[used] - found.sites[used] @ basis, axis=0)
    lattice = LensletLattice(found.kind, tuple(map(tuple, basis)), tuple(origin), found.sites)
    try:
        lattice.check_fits(frame.shape)
    except ValueError as error:
        raise InputError(f"{path}: {error}") from None
    centroider = Centroider.build(lattice, frame.shape)
    centres = lattice.centres()
    ideal = SpotMeasurement(centres, np.full(lattice.count, np.inf), np.ones(lattice.count, dtype=bool))
    return lattice, ideal, centroider.measure(frame)


def _check_pitch(path: Path, lattice: LensletLattice, args: argparse.Namespace) -> None:
    described = args.lenslet_pitch_um / args.pixel_um
    if abs(lattice.pitch_px / described - 1.0) > _PITCH_AGREEMENT:
        raise InputError(f"{path}: the spots are {lattice.pitch_px:.2f} px apart; --lenslet-pitch-um / --pixel-um "
                         f"give {described:.2f} px (expected within {_PITCH_AGREEMENT:.0%})")


def _used_lenslets(path: Path, reference: SpotMeasurement, spots: SpotMeasurement) -> np.ndarray:
    """Lenslets with a spot in both images, none much dimmer than the typical reference spot
    (the image's own typical spot when the reference is the ideal lattice)."""
    typical = reference.intensity[reference.valid & np.isfinite(reference.intensity)]
    if typical.size == 0:
        typical = spots.intensity[spots.valid]
    floor = _LIT_FRACTION * float(np.median(typical)) if typical.size else np.inf
    used = reference.valid & spots.valid & (spots.intensity >= floor)
    if not used.any():
        raise InputError(f"{path}: no spots in the lenslet windows; expected a Shack-Hartmann spot image")
    return used


def _pupil(lattice: LensletLattice, used: np.ndarray, given: tuple[float, float, float] | None
           ) -> tuple[float, float, float]:
    """The Zernike disk (col, row, radius), pixels: given, or about the used lenslets out to their edge."""
    if given is not None:
        return given
    centres = lattice.centres()[used]
    cx, cy = centres.mean(axis=0)
    return float(cx), float(cy), float(np.hypot(*(centres - (cx, cy)).T).max() + 0.5 * lattice.pitch_px)


def _reconstruct(path: Path, lattice: LensletLattice, reference: SpotMeasurement, spots: SpotMeasurement,
                 args: argparse.Namespace) -> dict[str, Any]:
    used = _used_lenslets(path, reference, spots)
    wavelength_um = args.wavelength_nm * 1e-3
    measured = SpotMeasurement(spots.centroids, spots.intensity, used)
    result = slopes(measured, reference, args.focal_length_mm * 1e3, args.pixel_um)
    sx, sy = convert_slopes(result, wavefront_unit_um=wavelength_um, length_unit_um=args.pixel_um)
    cx, cy, radius = _pupil(lattice, result.valid, args.pupil_px)
    modes = mode_list(args.ordering, args.modes)
    try:
        reconstructor = ModalReconstructor.for_circle(lattice.centres_xy(), (cx, -cy), radius, modes, result.valid)
    except ValueError as error:
        raise InputError(f"{path}: {error}") from None
    rms_coefficients = reconstructor.reconstruct(sx, sy)
    model_x, model_y = reconstructor.predict(rms_coefficients)
    misfit = np.concatenate([sx - model_x, sy - model_y])[np.concatenate([result.valid, result.valid])]
    tilt_measured = args.reference is not None
    reported = _reported(rms_coefficients, modes, args, tilt_measured)
    normalisation = default_normalisation(args.ordering)
    factors = np.array([normalisation_factor(n, m, "rms") / normalisation_factor(n, m, normalisation)
                        for n, m in modes])
    waves = [None if value is None else float(value * factor) for value, factor in zip(reported, factors)]
    known = np.array([0.0 if value is None else value for value in reported])
    rms = float(np.sqrt(np.sum(known[1:] ** 2)))  # orthonormal unit-RMS terms: RMS over the disk
    return {
        "files": [str(path)], "method": "shack-hartmann", "reference": args.reference,
        "lattice": {"kind": lattice.kind, "pitch_px": lattice.pitch_px, "orientation_deg": lattice.orientation_deg,
                    "origin": list(lattice.origin_px), "lenslets": lattice.count},
        "used_lenslets": int(result.valid.sum()), "pupil": [cx, cy, radius], "tilt_measured": tilt_measured,
        "wavelength_nm": args.wavelength_nm, "modes": len(modes), "ordering": args.ordering,
        "first_index": 0 if args.ordering == "ansi" else 1, "normalisation": normalisation,
        "mode_indices": [list(mode) for mode in modes], "coefficients_waves": waves,
        "coefficients_nm": [None if w is None else w * args.wavelength_nm for w in waves],
        "rms_waves": rms, "rms_nm": rms * args.wavelength_nm,
        "slope_residual_rms_waves_per_px": float(np.sqrt(np.mean(misfit**2))),
        "condition": reconstructor.condition,
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
