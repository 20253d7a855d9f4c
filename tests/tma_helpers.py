"""Shared pieces of the TMA tests: the example design and a Zernike fit with wavestack's basis."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wavestack.config.tma import load_tma_config
from wavestack.pipeline.zernike import noll_to_nm, zernike_basis

CONFIG = Path(__file__).resolve().parents[1] / "wavestack" / "config" / "tma-alignment.toml"


def example():
    """The design and as-built errors of ``wavestack/config/tma-alignment.toml``."""
    return load_tma_config(CONFIG)


def camera_xy_mm(design):
    """Camera-grid (x right, y up) coordinates of every pixel from the pupil centre, mm, shape (H, W)."""
    rows, cols = design.camera_shape
    x = (np.arange(cols) - (cols - 1) / 2) * design.pixel_mm
    y = ((rows - 1) / 2 - np.arange(rows)) * design.pixel_mm
    return np.meshgrid(x, y)


def fit_noll(design, wavefront, count=11):
    """Noll coefficients 1..count (waves, RMS-normalised) on the circle through the pupil's corners."""
    xx, yy = camera_xy_mm(design)
    ok = np.isfinite(wavefront)
    radius = float(np.hypot(*design.pupil.size_mm) / 2)
    modes = [noll_to_nm(j) for j in range(1, count + 1)]
    basis = zernike_basis(modes, xx[ok] / radius, yy[ok] / radius)
    coefficients, *_ = np.linalg.lstsq(basis, wavefront[ok], rcond=None)
    return coefficients  # index j-1 holds Noll j
