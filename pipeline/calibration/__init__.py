"""Absolute tests: separating the part's figure from the reference's.

:func:`solve_rotation_test` is the N-position rotation test (Evans & Kestner) in the fitted basis;
:func:`rotate_coefficients` turns a figure's Zernike coefficients about the disk's centre.

>>> from wavestack.pipeline.calibration import solve_rotation_test
"""

from __future__ import annotations

from .rotation import RotationSolution, angular_orders, rotate_coefficients, solve_rotation_test

__all__ = ["RotationSolution", "angular_orders", "rotate_coefficients", "solve_rotation_test"]
