"""Accuracy figures behind the README's numerical notes.

Run:  .venv/bin/python benchmarks/bench_numerics.py

1. Radial polynomials: the recurrence of ``wavestack.pipeline.zernike`` and the explicit
   factorial sum in float64, each against exact rational arithmetic (``fractions.Fraction``) at
   49 rational radii in [0, 1], for every m at n = 20, 30, 40, 50: the largest absolute error.
2. Orthonormality of all 231 modes up to n = 20 on an exact polar quadrature.
3. On a 3.5:1 rounded rectangle (36 Noll modes, circle basis, exact data of 0.02-wave terms):
   the coefficient error of a Cholesky solve of the normal equations against that of the
   fitter, which projects onto the orthonormalised operator.
"""

from __future__ import annotations

from fractions import Fraction
from math import comb

import numpy as np
import scipy.linalg

from wavestack.bench import rounded_rectangle_mask
from wavestack.pipeline import build_fitter, mode_list, zernike_basis, zernike_radial


def exact_radial(n: int, m: int, rho: Fraction) -> Fraction:
    """R_n^m(rho) from the factorial sum, in exact arithmetic."""
    k_max = (n - m) // 2
    return sum(
        (-1) ** k * comb(n - k, k) * comb(n - 2 * k, k_max - k) * rho ** (n - 2 * k)
        for k in range(k_max + 1)
    )


def float_factorial_sum(n: int, m: int, rho: np.ndarray) -> np.ndarray:
    """R_n^m(rho) from the factorial sum in float64 (the way not to do it)."""
    k_max = (n - m) // 2
    return sum(
        (-1) ** k * float(comb(n - k, k) * comb(n - 2 * k, k_max - k)) * rho ** (n - 2 * k)
        for k in range(k_max + 1)
    )


def radial_accuracy() -> None:
    radii = [Fraction(i, 48) for i in range(49)]
    rho = np.array([float(r) for r in radii])
    print("| n | recurrence max error | factorial sum max error |")
    print("|---:|---:|---:|")
    for n in (20, 30, 40, 50):
        worst_recurrence = worst_sum = 0.0
        for m in range(n % 2, n + 1, 2):
            exact = np.array([float(exact_radial(n, m, r)) for r in radii])
            worst_recurrence = max(worst_recurrence, np.abs(zernike_radial(n, m, rho) - exact).max())
            worst_sum = max(worst_sum, np.abs(float_factorial_sum(n, m, rho) - exact).max())
        print(f"| {n} | {worst_recurrence:.2g} | {worst_sum:.2g} |")


def orthonormality() -> None:
    nodes, weights = np.polynomial.legendre.leggauss(40)
    rho = (nodes + 1) / 2
    theta = np.arange(64) * 2 * np.pi / 64
    r, t = np.meshgrid(rho, theta, indexing="ij")
    w = np.outer(weights / 2 * rho, np.full(64, 1 / 64)) * 2  # (1/pi) * rho drho dtheta
    basis = zernike_basis(mode_list("noll", 231), (r * np.cos(t)).ravel(), (r * np.sin(t)).ravel())
    gram = basis.T @ (basis * w.ravel()[:, None])
    print(f"orthonormality, 231 modes (n <= 20): max |G - I| = {np.abs(gram - np.eye(231)).max():.2g}")


def normal_equations_vs_orthonormal() -> None:
    mask = rounded_rectangle_mask((90, 260), 120.0, 34.0, 12.0)
    fitter = build_fitter(mask, modes=36, dtype=np.float64)
    pupil = fitter.basis.pupil
    rows, cols = np.nonzero(mask)
    design = zernike_basis(
        mode_list("noll", 36), (cols - pupil.cx) / pupil.radius, (pupil.cy - rows) / pupil.radius
    )
    truth = np.random.default_rng(1).normal(0, 0.02, 36)
    data = design @ truth
    cholesky = scipy.linalg.cho_solve(scipy.linalg.cho_factor(design.T @ design), design.T @ data)
    frame = np.full(mask.shape, np.nan)
    frame[rows, cols] = data
    fitted = fitter.fit(frame).coefficients
    print(f"3.5:1 rectangle, 36 modes: kappa(G) = {fitter.diagnostics.gram_condition:.3g}, "
          f"noise gain {fitter.diagnostics.noise_gain:.3g}")
    print(f"  coefficient error, Cholesky of H^T H: {np.abs(cholesky - truth).max():.2g} waves")
    print(f"  coefficient error, fitter (Q from CholeskyQR2): {np.abs(fitted - truth).max():.2g} waves")


if __name__ == "__main__":
    radial_accuracy()
    orthonormality()
    normal_equations_vs_orthonormal()
