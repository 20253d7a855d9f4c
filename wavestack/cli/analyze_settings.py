"""What ``wavestack analyze`` measures interferograms with: its own options, or a station's ``--config``.

Either way the result is one :class:`~wavestack.pipeline.InterferometerSettings` for the one
processor every command runs. With ``--config STATION.toml`` the ``[processing]`` table of a
station is applied to the files (phase algorithm and steps, fit method and grid, the quality mask
and spike clipping, the camera's full scale), so the files give the numbers the station gives for
the same frames; the processing options of the command line are then refused (the file says them),
while the aperture choice, the null test and the outputs still apply. Without it, analyze's own
defaults: least squares with equal steps (or one carrier frame), the full-resolution grid, the
``auto`` fit in float64, no residual limit.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from wavestack.config import ConfigError, StationConfig, load_station_config
from wavestack.pipeline import InputError
from wavestack.pipeline.calibration import CalibrationRefused, read_calibration
from wavestack.pipeline.instrument import ConicNull, FitSettings, InterferometerSettings, QualitySettings
from wavestack.pipeline.zernike import ConicTest
from wavestack.station import interferometer_settings

__all__ = ["ANALYZE_DEFAULTS", "PROCESSING_OPTIONS", "analyze_settings", "conic_test", "station_config",
           "steps_argument", "with_defaults"]

#: analyze's own values of the processing options it leaves unset on the command line.
ANALYZE_DEFAULTS: dict[str, Any] = {"modes": 36, "ordering": "noll", "fit_method": "auto", "direction": "ccw",
                                    "carrier_sign": 1, "clip_sigma": 6.0}
#: Options a ``--config`` file's ``[processing]`` table decides: attribute -> flag.
PROCESSING_OPTIONS = {"method": "--method", "steps": "--steps", "direction": "--direction",
                      "carrier_sign": "--carrier-sign", "modes": "--modes", "ordering": "--ordering",
                      "fit_method": "--fit-method", "obscuration": "--obscuration", "remove": "--remove",
                      "clip_sigma": "--clip-sigma", "no_clip": "--no-clip", "min_modulation": "--min-modulation"}


def station_config(args: argparse.Namespace) -> StationConfig | None:
    """The ``--config`` station, checked to be an interferometer whose processing the options do not contradict.

    Raises
    ------
    InputError
        The file is not a valid station, is a Shack-Hartmann station, or a processing option is given beside it.
    """
    if getattr(args, "config", None) is None:
        return None
    try:
        config = load_station_config(Path(args.config))
    except ConfigError as error:
        raise InputError(str(error)) from None
    if config.station.kind != "interferometer":
        raise InputError(f"{args.config}: analyze --config takes an interferometer station; this one is "
                         f"{config.station.kind!r}")
    given = [flag for name, flag in PROCESSING_OPTIONS.items() if getattr(args, name, None) not in (None, False)]
    if given:
        raise InputError(f"{args.config}: {', '.join(given)} given beside --config; the station's [processing] "
                         "table decides them: drop the option(s) or the --config")
    return config


def with_defaults(args: argparse.Namespace) -> argparse.Namespace:
    """``args`` with analyze's own defaults where a processing option was left unset."""
    values = vars(args).copy()
    for name, value in ANALYZE_DEFAULTS.items():
        if values.get(name) is None:
            values[name] = value
    return argparse.Namespace(**values)


def analyze_settings(args: argparse.Namespace, frame_count: int, config: StationConfig | None,
                     wavelength_nm: float) -> InterferometerSettings:
    """The settings the files are measured with (module notes).

    Raises
    ------
    InputError
        A method the frame count cannot take, or steps of another count than the frames.
    """
    null = _null(args, wavelength_nm)
    aperture = args.aperture if args.mask is None else "detected"
    if config is not None:
        settings = interferometer_settings(config)
        return _calibrated(args, dataclasses.replace(settings, aperture=aperture, null=null), wavelength_nm)
    first = args.files[0]
    if frame_count == 1 and args.method not in (None, "carrier"):
        raise InputError(f"{first}: one frame can only be analysed by the carrier method; got --method {args.method}")
    if frame_count > 1 and args.method == "carrier":
        raise InputError(f"{first}: the carrier method takes one frame; got {frame_count}")
    if args.steps is not None and len(args.steps) != frame_count:
        raise InputError(f"{first}: --steps gives {len(args.steps)} steps for {frame_count} frames")
    fit = FitSettings(method=args.fit_method, modes=args.modes, ordering=args.ordering, remove=args.remove,
                      obscuration=args.obscuration, dtype="float64")
    quality = QualitySettings() if args.min_modulation is None else QualitySettings(min_modulation=args.min_modulation)
    return _calibrated(args, InterferometerSettings(
        method="carrier" if frame_count == 1 else "psi",
        psi_algorithm={None: "lsq", "psi": "lsq", "aia": "aia", "pca": "pca", "carrier": "lsq"}[args.method],
        steps_rad=None if args.steps is None else tuple(float(s) for s in args.steps), direction=args.direction,
        carrier_sign=args.carrier_sign, aperture=aperture, fit=fit, quality=quality,
        clip_sigma=None if args.no_clip else args.clip_sigma, null=null), wavelength_nm)


def _calibrated(args: argparse.Namespace, settings: InterferometerSettings,
                wavelength_nm: float) -> InterferometerSettings:
    """``settings`` with ``--calibration`` in force (read, its hash and wavelength checked)."""
    if getattr(args, "calibration", None) is None:
        return settings
    try:
        calibration = read_calibration(args.calibration)
        calibration.check_measurement(calibration.grid, wavelength_nm)
    except CalibrationRefused as error:
        raise InputError(f"--calibration {error}") from None
    return dataclasses.replace(settings, calibration=calibration)


def _null(args: argparse.Namespace, wavelength_nm: float) -> ConicNull | None:
    if args.null_conic is None:
        return None
    return ConicNull(conic_test(args, wavelength_nm), float(args.null_conic))


def conic_test(args: argparse.Namespace, wavelength_nm: float) -> ConicTest:
    """The mirror of ``--roc-mm`` and ``--diameter-mm`` at ``wavelength_nm``.

    Raises
    ------
    InputError
        If either is missing.
    """
    if args.roc_mm is None or args.diameter_mm is None:
        raise InputError("--null-conic and the implied conic need both --roc-mm and --diameter-mm")
    return ConicTest(args.roc_mm, args.diameter_mm, wavelength_nm)


def steps_argument(text: str) -> np.ndarray:
    """``--steps``: phase steps in degrees, comma-separated, to radians."""
    try:
        values = np.array([float(v) for v in text.split(",")])
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected phase steps in degrees, e.g. 0,60,120, got {text!r}") from None
    if not np.isfinite(values).all():
        raise argparse.ArgumentTypeError(f"expected finite phase steps in degrees, e.g. 0,60,120, got {text!r}")
    return np.deg2rad(values)
