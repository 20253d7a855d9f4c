"""Absolute tests: separating the part's figure from the reference's.

:func:`solve_rotation_test` is the N-position rotation test (Evans & Kestner) in the fitted basis;
:func:`rotate_coefficients` turns a figure's Zernike coefficients about the disk's centre;
:class:`ReferenceCalibration` is a stored calibration (its HDF5 file with a content hash:
:func:`write_calibration`, :func:`read_calibration`) and the correction every measurement subtracts.

>>> from wavestack.pipeline.calibration import solve_rotation_test
"""

from __future__ import annotations

from .rotation import RotationSolution, angular_orders, rotate_coefficients, solve_rotation_test
from .stored import CalibrationRefused, ReferenceCalibration, content_digest, read_calibration, write_calibration

__all__ = ["CalibrationRefused", "ReferenceCalibration", "RotationSolution", "angular_orders", "content_digest",
           "read_calibration", "rotate_coefficients", "solve_rotation_test", "write_calibration"]
