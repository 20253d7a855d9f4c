"""Benchmark of wavestack's refit against the Zernike fits of prysm, poppy and hcipy.

Run:  .venv/bin/pip install -e '.[bench]' && .venv/bin/python benchmarks/bench_peers.py [--size 512] [--modes 36]

Input: a square frame whose pupil is the inscribed disk (radius size/2 px, the grid of all three
peers: pixel centres at ``(i - (size - 1)/2) / (size/2)``), holding Noll-ordered unit-RMS Zernike
terms with m >= 0 only (radial and cosine terms, the same in every library whatever its sign of y
or angle) plus 1e-4 noise. Every path's coefficients are checked against the truth before any
timing (the largest error over the modes, relative to the largest true coefficient; the peers'
own basis conventions and sampling leave ~1e-3). The paths then run interleaved, one of each per
round, and the medians are printed with the ratio to wavestack's refit:

* wavestack: ``fitter.fit(frame)`` (float32 and float64 frames; moment refit);
* prysm: ``prysm.polynomials.lstsq`` of the frame on precomputed ``zernike_nm`` modes;
* poppy: ``poppy.zernike.opd_expand`` (basis computed per call), and with a cached basis cube;
* hcipy: ``ModeBasis.coefficients_for`` (a least-squares solve per call), and a precomputed
  ``inverse_tikhonov`` pseudo-inverse applied by one matrix product.

The peers are the optional ``bench`` extra of pyproject.toml, not runtime dependencies. A peer
that does not import is reported and left out. BLAS threads are pinned (default 1).
"""

from __future__ import annotations

import argparse
import os
import sys


def _parse() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=512, help="frame side, pixels (512)")
    parser.add_argument("--modes", type=int, default=36, help="Noll modes (36)")
    parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds per median (5)")
    parser.add_argument("--threads", type=int, default=1, help="BLAS threads (1)")
    return parser.parse_args()


ARGS = _parse()
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = str(ARGS.threads)

import importlib  # noqa: E402
import logging  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

from wavestack.pipeline import build_fitter, mode_list, zernike_basis  # noqa: E402

# Largest coefficient error accepted, relative to the largest true coefficient: least-squares paths
# recover the truth to the noise (~1e-5); poppy's opd_expand takes inner products as if the modes
# were orthonormal on the pixels, which they are only to a few percent at a pixelated edge.
TRUTH_TOLERANCE = 1e-3
INNER_PRODUCT_TOLERANCE = 5e-2


def setup(size: int, modes: int):
    """Grid, mask, the Noll (n, m) list, the truth and the frame (float64, NaN outside)."""
    half = size / 2.0
    idx = (np.arange(size) - (size - 1) / 2.0) / half
    x, y = np.meshgrid(idx, -idx)  # x right, y up (row 0 on top)
    mask = x * x + y * y <= 1.0
    nm = mode_list("noll", modes)
    rng = np.random.default_rng(1)
    truth = np.array([rng.normal(0, 0.1) if m >= 0 else 0.0 for n, m in nm])
    frame = np.full((size, size), np.nan)
    frame[mask] = zernike_basis(nm, x[mask], y[mask]) @ truth + rng.normal(0, 1e-4, int(mask.sum()))
    return x, y, mask, nm, truth, frame


def wavestack_paths(x, y, mask, nm, frame) -> dict[str, tuple[object, object]]:
    """name -> (call, how to read its coefficients)."""
    size = mask.shape[0]
    pupil = ((size - 1) / 2.0, (size - 1) / 2.0, size / 2.0)
    paths = {}
    for dtype in (np.float32, np.float64):
        fitter = build_fitter(mask, modes=len(nm), pupil=pupil, dtype=dtype)
        data = frame.astype(dtype)
        paths[f"wavestack {np.dtype(dtype).name} ({fitter.refit})"] = (
            lambda f=fitter, d=data: f.fit(d), lambda r: r.coefficients)
    return paths


def prysm_paths(x, y, mask, nm, frame):
    polynomials = importlib.import_module("prysm.polynomials")
    r, t = np.hypot(x, y), np.arctan2(y, x)
    modes = [polynomials.zernike_nm(n, m, r, t, norm=True) for n, m in nm]
    return {"prysm lstsq (modes precomputed)": (lambda: polynomials.lstsq(modes, frame), np.asarray)}


def poppy_paths(x, y, mask, nm, frame):
    zernike = importlib.import_module("poppy.zernike")
    opd = np.where(mask, frame, 0.0)
    cube = zernike.zernike_basis(nterms=len(nm), npix=mask.shape[0], outside=np.nan)
    mask = mask & np.isfinite(cube).all(axis=0)  # poppy's own disk drops edge pixels of ours

    def cached(**_: object) -> np.ndarray:
        return cube

    return {
        "poppy opd_expand": (lambda: zernike.opd_expand(opd, aperture=mask, nterms=len(nm)), np.asarray),
        "poppy opd_expand (cached basis)": (
            lambda: zernike.opd_expand(opd, aperture=mask, nterms=len(nm), basis=cached), np.asarray),
    }


def hcipy_paths(x, y, mask, nm, frame):
    hcipy = importlib.import_module("hcipy")
    grid = hcipy.make_pupil_grid(mask.shape[0], 2.0)
    basis = hcipy.make_zernike_basis(len(nm), 2.0, grid, starting_mode=1)
    data = np.where(mask, frame, 0.0)[::-1].ravel()  # hcipy's y grows with the row index
    inverse = hcipy.inverse_tikhonov(np.asarray(basis.transformation_matrix), rcond=1e-15)
    return {
        "hcipy coefficients_for": (lambda: basis.coefficients_for(data), np.asarray),
        "hcipy inverse_tikhonov (precomputed)": (lambda: inverse.dot(data), np.asarray),
    }


def checked(name: str, call, read, truth: np.ndarray) -> float:
    """Largest coefficient error (absolute values: signs of odd terms differ between libraries)."""
    coefficients = np.asarray(read(call()), dtype=np.float64)[: truth.size]
    error = float(np.max(np.abs(np.abs(coefficients) - np.abs(truth))) / np.max(np.abs(truth)))
    limit = INNER_PRODUCT_TOLERANCE if name.startswith("poppy") else TRUTH_TOLERANCE
    print(f"truth check  {name:<42} max error {error:.1e} (limit {limit:.0e})  {'ok' if error <= limit else 'FAILED'}")
    return error / limit


def main() -> int:
    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    x, y, mask, nm, truth, frame = setup(ARGS.size, ARGS.modes)
    print(f"# bench_peers: {ARGS.size} x {ARGS.size} frame, {int(mask.sum())} pupil pixels, {ARGS.modes} Noll "
          f"modes, {ARGS.rounds} interleaved rounds, BLAS threads {ARGS.threads}, load {os.getloadavg()[0]:.1f}")
    paths = wavestack_paths(x, y, mask, nm, frame)
    for peer, make in (("prysm", prysm_paths), ("poppy", poppy_paths), ("hcipy", hcipy_paths)):
        try:
            paths.update(make(x, y, mask, nm, frame))
        except ImportError as error:
            print(f"{peer}: not installed ({error}); left out")
    failed = [name for name, (call, read) in paths.items() if checked(name, call, read, truth) > 1.0]
    times: dict[str, list[float]] = {name: [] for name in paths if name not in failed}
    for _ in range(ARGS.rounds):
        for name in times:
            started = time.perf_counter()
            paths[name][0]()
            times[name].append(time.perf_counter() - started)
    medians = {name: float(np.median(values)) for name, values in times.items()}
    reference = next(v for k, v in medians.items() if k.startswith("wavestack float32"))
    print("\n| path | median ms | x wavestack float32 |\n|---|---:|---:|")
    for name, seconds in medians.items():
        print(f"| {name} | {seconds * 1e3:.2f} | {seconds / reference:.1f} |")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
