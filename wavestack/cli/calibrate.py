"""``wavestack calibrate rotation``: the N-position rotation test of the part on a PI rotation stage.

Without ``--config`` it measures the packaged simulated calibration station (a 128 x 128 camera, a
reference carrying 20 nm RMS of non-symmetric error) and without ``--stage`` the packaged simulated
rotation stage, both started by the command. It turns the part to N equally spaced angles, averages
``--maps`` maps per position robustly, separates the part's non-symmetric figure from the
reference's in the fitted basis, and prints the reference's and the part's RMS with their
uncertainty, the orders it cannot separate (0 and multiples of N), and per position the angle read
back and the maps rejected; with a simulated station also the error of both against the simulator's
truth. ``--json`` prints one JSON object instead. ``--out CAL.h5`` writes the reference's calibration
(:mod:`wavestack.pipeline.calibration.stored`), only once the calibration succeeded.

Exit status: 0 with the answer; 3 when the calibration fails (the stage stalls, refuses or is lost,
the station gives no trusted maps; one line names the position and the reason, nothing is written);
130 when stopped by Ctrl-C or SIGTERM.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import sys
import threading
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from wavestack.calibrate import (
    BallTestSettings,
    CalibrationFailed,
    RotationCalibration,
    RotationSettings,
    ball_reference,
    calibrate_reference,
    calibrate_rotation,
    reference_calibration,
)
from wavestack.cli.arguments import finite_float, positive_int
from wavestack.cli.command import Command
from wavestack.cli.outputs import check_output_file, json_text
from wavestack.cli.signals import stop_on_signals
from wavestack.config.hexapod import build_hexapod
from wavestack.config.rotation_stage import load_rotation_stage_config
from wavestack.config.station import load_station_config
from wavestack.pipeline import InputError
from wavestack.pipeline.calibration import ReferenceCalibration, write_calibration
from wavestack.station import StationService

__all__ = ["COMMAND", "rotation_report"]

#: The packaged simulated calibration station.
CALIBRATION_STATION = Path(__file__).resolve().parents[1] / "config" / "calibration-station.toml"
#: The packaged simulated random ball station.
BALL_STATION = Path(__file__).resolve().parents[1] / "config" / "calibration-ball-station.toml"
EXIT_FAILED = 3
EXIT_STOPPED = 130


def add_calibrate_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``wavestack calibrate``: one sub-command per method."""
    methods = parser.add_subparsers(dest="method", required=True, metavar="METHOD")
    rotation = methods.add_parser(
        "rotation", help="N-position rotation test: the part's and the reference's non-symmetric figure",
        description="Turn the part to N equally spaced angles on the rotation stage, measure each, derotate in "
                    "the fitted basis and separate the part's non-rotationally-symmetric figure from the "
                    "reference's, except the angular orders kN (named in the output).")
    rotation.add_argument("--positions", type=positive_int, default=4, metavar="N", help="rotations (>= 2; default 4)")
    rotation.add_argument("--maps", type=positive_int, default=8, metavar="M",
                          help="valid maps averaged per position (>= 3; default 8)")
    rotation.add_argument("--stage", type=Path, help="rotation stage TOML, [rotation_stage] (default: simulated)")
    rotation.add_argument("--start-deg", type=finite_float, default=0.0, metavar="DEG", help="first angle (default 0)")
    _add_measuring_options(rotation, "the simulated calibration station", "the stage arrived")
    ball = methods.add_parser(
        "reference", help="random ball test: the reference's error from N seatings of a calibration ball",
        description="Measure a calibration ball at the confocal position in N random seatings (the operator "
                    "re-seats it when asked; the simulated ball is re-seated by the command) and average: the "
                    "reference's error with its per-pixel and per-coefficient uncertainty.")
    ball.add_argument("--seatings", type=positive_int, default=32, metavar="N", help="seatings (>= 3; default 32)")
    ball.add_argument("--maps", type=positive_int, default=4, metavar="M",
                      help="valid maps averaged per seating (>= 3; default 4)")
    _add_measuring_options(ball, "the simulated ball station", "the seating")


def _add_measuring_options(parser: argparse.ArgumentParser, default_station: str, settled_after: str) -> None:
    """The options every calibration method shares: the station, the maps' settling, the fit, the output."""
    parser.add_argument("--config", type=Path, help=f"station TOML (default: {default_station})")
    parser.add_argument("--settle-s", type=finite_float, default=0.2, metavar="S",
                        help=f"maps count only if exposed this long after {settled_after} (default 0.2)")
    parser.add_argument("--modes", type=positive_int, default=36, metavar="J", help="Noll terms fitted (default 36)")
    parser.add_argument("--edge-px", type=int, default=2, metavar="PX", help="rim pixels left out (default 2)")
    parser.add_argument("--out", type=Path, metavar="CAL.h5",
                        help="write the reference's calibration (HDF5, with its content hash); never overwritten")
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def run_calibrate(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Run ``wavestack calibrate rotation`` or ``wavestack calibrate reference``."""
    rotation = args.method == "rotation"
    try:
        settings = (RotationSettings(positions=args.positions, maps_per_position=args.maps, start_deg=args.start_deg,
                                     settle_s=args.settle_s, modes=args.modes, edge_px=args.edge_px) if rotation else
                    BallTestSettings(seatings=args.seatings, maps_per_seating=args.maps, settle_s=args.settle_s,
                                     modes=args.modes, edge_px=args.edge_px))
    except ValueError as error:
        parser.error(str(error))
    out = None
    if args.out is not None:
        out = check_output_file(args.out, "--out")
        if out.exists():
            raise InputError(f"{out}: exists already; --out never overwrites a calibration")
    station_config = load_station_config(args.config or (CALIBRATION_STATION if rotation else BALL_STATION))
    wavelength = station_config.station.wavelength_nm
    stop = threading.Event()
    with ExitStack() as stack:
        service = StationService(station_config, stack, name="calibrate-station")
        try:
            with stop_on_signals(stop):
                if rotation:
                    report, stored = _rotation(args, settings, service, stack, stop, wavelength)
                else:
                    report, stored = _ball(args, settings, service, stop, wavelength)
        except CalibrationFailed as error:
            if stop.is_set():
                print("wavestack calibrate: stopped; nothing written", file=sys.stderr)
                return EXIT_STOPPED
            print(f"wavestack calibrate: {error}; nothing written", file=sys.stderr)
            return EXIT_FAILED
        if out is not None:
            written = write_calibration(out, stored)
            report["calibration_file"] = {"path": str(out), "sha256": written.digest}
    print(json_text(report) if args.json else _text(report))
    return 0


def _rotation(args: argparse.Namespace, settings: RotationSettings, service: StationService, stack: ExitStack,
              stop: threading.Event, wavelength: float) -> tuple[dict[str, object], ReferenceCalibration]:
    stage_config = load_rotation_stage_config(args.stage)
    on_arrival, truth, url = None, None, stage_config.stage.url
    if stage_config.simulated:
        from wavestack.simulated import start_rotation_stage  # a real stage loads no simulator

        simulated = start_rotation_stage(stage_config, getattr(service.devices.bench, "optic", None), stack)
        on_arrival, truth, url = simulated.turn_part, simulated.truth_errors, simulated.url
    stage = build_hexapod(dataclasses.replace(stage_config.stage, url=url))
    stage.open()
    stack.callback(stage.close)
    calibration = calibrate_rotation(service.maps, stage, settings, on_arrival=on_arrival, stop=stop)
    report = rotation_report(calibration, wavelength)
    if truth is not None:
        report["truth"] = truth(calibration, wavelength)
    return report, reference_calibration(calibration, wavelength, _now())


def _ball(args: argparse.Namespace, settings: BallTestSettings, service: StationService, stop: threading.Event,
          wavelength: float) -> tuple[dict[str, object], ReferenceCalibration]:
    optic = getattr(service.devices.bench, "optic", None)
    if service.config.camera.simulated:
        from wavestack.simulated import ball_seating, reference_truth_errors  # a real bench loads no simulator

        seat = ball_seating(optic)
    else:
        seat = _operator_seats
    calibration = calibrate_reference(service.maps, seat, settings, stop=stop)
    stored = ball_reference(calibration, wavelength, _now())
    mask = calibration.mask
    report: dict[str, object] = {
        "method": "random-ball", "seatings": settings.seatings, "wavelength_nm": wavelength, "grid": list(mask.shape),
        "aperture_pixels": int(mask.sum()), "seatings_kept": calibration.average.count,
        "seatings_rejected": list(calibration.average.rejected),
        "reference_nm_rms": float(np.nanstd(stored.reference_waves[mask]) * wavelength),
        "reference_uncertainty_nm_rms": float(np.sqrt(np.nanmean(stored.reference_stderr_waves[mask] ** 2))
                                              * wavelength),
        "left_out": "piston, tilt, power (alignment)",
    }
    if service.config.camera.simulated:
        report["truth"] = reference_truth_errors(optic, calibration, wavelength)
    return report, stored


def _operator_seats(index: int) -> None:
    """A real bench: the operator re-seats the ball at a fresh orientation, then presses Enter."""
    print(f"seating {index + 1}: re-seat the ball at a new orientation, then press Enter", file=sys.stderr)
    if not sys.stdin.readline():
        raise CalibrationFailed(f"seating {index + 1}: no operator (standard input closed)")


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def rotation_report(calibration: RotationCalibration, wavelength_nm: float) -> dict[str, object]:
    """The JSON-ready summary of a rotation calibration (nm of wavefront)."""
    solution = calibration.solution
    mask = calibration.mask

    def rms_nm(values: np.ndarray) -> float:
        inside = values[mask]
        return float(np.sqrt(np.mean((inside - inside.mean()) ** 2)) * wavelength_nm)

    return {
        "method": "rotation", "positions": solution.positions, "wavelength_nm": wavelength_nm,
        "grid": list(mask.shape), "aperture_pixels": int(mask.sum()),
        "unresolved_orders": list(solution.unresolved_orders),
        "reference_nm_rms": rms_nm(calibration.reference_map),
        "reference_uncertainty_nm_rms": float(np.sqrt(np.nanmean(calibration.reference_stderr_map[mask] ** 2))
                                              * wavelength_nm),
        "part_nm_rms": rms_nm(calibration.part_map),
        "positions_measured": [{"target_deg": r.target_deg, "angle_deg": r.angle_deg, "kept": r.average.count,
                                "rejected": list(r.average.rejected)} for r in calibration.records],
    }


def _text(report: dict[str, object]) -> str:
    if report["method"] == "random-ball":
        return _ball_text(report)
    lines = [f"rotation test, N = {report['positions']}: reference {report['reference_nm_rms']:.2f} nm RMS "
             f"(+- {report['reference_uncertainty_nm_rms']:.2f} nm), part {report['part_nm_rms']:.2f} nm RMS "
             f"(non-symmetric, orders {report['unresolved_orders']} not separated)"]
    for index, position in enumerate(report["positions_measured"]):  # type: ignore[arg-type]
        lines.append(f"  position {index + 1}: {position['angle_deg']:.4f} deg, {position['kept']} map(s) kept, "
                     f"rejected {position['rejected'] or 'none'}")
    written = report.get("calibration_file")
    if isinstance(written, dict):
        lines.append(f"  calibration written: {written['path']} (sha256 {written['sha256'][:12]})")
    truth = report.get("truth")
    if isinstance(truth, dict) and "part_error_nm_rms" in truth:
        lines.append(f"  against the simulator's truth: part {truth['part_error_nm_rms']:.3f} nm RMS, reference "
                     f"{truth['reference_error_nm_rms']:.3f} nm RMS")
    return "\n".join(lines)


def _ball_text(report: dict[str, object]) -> str:
    lines = [f"random ball test, {report['seatings_kept']} of {report['seatings']} seatings kept "
             f"(rejected {report['seatings_rejected'] or 'none'}): reference {report['reference_nm_rms']:.2f} nm RMS "
             f"(+- {report['reference_uncertainty_nm_rms']:.2f} nm; {report['left_out']} left out)"]
    written = report.get("calibration_file")
    if isinstance(written, dict):
        lines.append(f"  calibration written: {written['path']} (sha256 {written['sha256'][:12]})")
    truth = report.get("truth")
    if isinstance(truth, dict):
        lines.append(f"  against the simulator's truth: reference {truth['reference_error_nm_rms']:.3f} nm RMS")
    return "\n".join(lines)


COMMAND = Command(
    "calibrate",
    help="calibrate the instrument against its reference (rotation: the N-position test; reference: random ball)",
    description="Absolute tests of the interferometer: separate the part's figure from the reference's.",
    add_arguments=add_calibrate_arguments, handler=run_calibrate,
    subject=lambda args: str(args.config) if getattr(args, "config", None) else "the simulated calibration station",
)
