"""Benchmark of the signal path at 1024 x 1024: each stage against one memory pass of its input.

Run:  .venv/bin/python benchmarks/bench_signal.py [--repeats 30]

BLAS and OpenCV pinned to one thread. Inputs are synthetic: a disk aperture of radius 448 px
with a smooth wavefront of a few tens of radians and tilt fringes, uint8 frames as a camera
gives them. For each stage it prints the median and p99 over ``--repeats`` runs and the ratio
of the median to one numpy read pass (``sum``) over the stage's input, measured in the same run.
Shack-Hartmann: 40 x 40 lenslets of 25 px on a 1280 x 1024 uint16 frame, centroiding plus a
15-mode modal reconstruction.
"""

from __future__ import annotations

import argparse
import os
import sys

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"

import time  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from wavestack.pipeline import detect_aperture, mode_list  # noqa: E402
from wavestack.pipeline import ApertureWatch  # noqa: E402
from wavestack.pipeline import carrier_phase  # noqa: E402
from wavestack.pipeline import four_step, hariharan_five_step  # noqa: E402
from wavestack.pipeline import Centroider, LensletLattice, slopes  # noqa: E402
from wavestack.pipeline.instrument import ShackHartmannProcessor, ShackHartmannSetup  # noqa: E402
from wavestack.pipeline import ModalReconstructor  # noqa: E402
from wavestack.pipeline import TemporalUnwrapper, unwrap_spatial  # noqa: E402

SIZE = 1024


def timed(action, repeats: int) -> tuple[float, float]:
    """Median and 99th percentile wall time of ``action()`` in seconds, after one warm-up."""
    action()
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        action()
        times.append(time.perf_counter() - started)
    return float(np.median(times)), float(np.percentile(times, 99))


def scene() -> tuple[np.ndarray, np.ndarray]:
    rows, cols = np.indices((SIZE, SIZE), dtype=np.float64)
    x, y = (cols - 511.5) / 448, (511.5 - rows) / 448
    mask = x * x + y * y <= 1.0
    phase = 12.0 * (x * x + y * y) + 3.0 * x**3 + 2.0 * y  # radians
    return mask, np.where(mask, phase, 0.0)


def frames_for(phase: np.ndarray, mask: np.ndarray, steps: np.ndarray) -> np.ndarray:
    background = np.where(mask, 120.0, 15.0)
    amplitude = np.where(mask, 90.0, 5.0)
    stack = background + amplitude * np.cos(phase[None] + steps[:, None, None])
    return np.clip(stack, 0, 255).astype(np.uint8)


def spot_frame(grid: LensletLattice, shift: np.ndarray) -> np.ndarray:
    rows, cols = np.indices((1024, 1280), dtype=np.float32)
    frame = np.zeros((1024, 1280), np.float32)
    centres = grid.centres() + shift
    for cx, cy in centres:
        r0, c0 = int(cy) - 6, int(cx) - 6
        window = (slice(max(r0, 0), r0 + 13), slice(max(c0, 0), c0 + 13))
        frame[window] += 4000 * np.exp(-((rows[window] - cy) ** 2 + (cols[window] - cx) ** 2) / 4.5)
    return frame.astype(np.uint16)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    n = args.repeats
    mask, phase = scene()
    rows = []

    def row(name: str, action, pass_input) -> None:
        median, p99 = timed(action, n)
        memory, _ = timed(lambda: [np.sum(a) for a in pass_input], n)
        rows.append((name, median, p99, memory))

    four = frames_for(phase, mask, np.arange(4) * np.pi / 2)
    five = frames_for(phase, mask, np.arange(5) * np.pi / 2)
    modulation = np.where(mask, 90.0, 5.0) + np.random.default_rng(0).normal(0, 3, mask.shape)
    rows_i, cols_i = np.indices((SIZE, SIZE))
    carrier = frames_for(phase + 2 * np.pi * cols_i / 12.0, mask, np.zeros(1))[0]
    wrapped = np.angle(np.exp(1j * phase))
    row("mask (detect_aperture on the modulation)", lambda: detect_aperture(modulation), [modulation])
    found = detect_aperture(modulation)
    watch = ApertureWatch(found.aperture.mask, found.threshold)
    row("mask check per frame (ApertureWatch, the station's steady state)", lambda: watch.check(modulation),
        [modulation])
    row("4-step PSI (uint8 frames)", lambda: four_step(four), [four])
    row("5-step Hariharan (uint8 frames)", lambda: hariharan_five_step(five), [five])
    row("carrier method (uint8 frame)", lambda: carrier_phase(carrier), [carrier])
    row("spatial unwrap (histogram)", lambda: unwrap_spatial(wrapped, mask), [wrapped])
    unwrapper = TemporalUnwrapper()
    unwrapper.update(wrapped, mask)
    drift = [np.angle(np.exp(1j * (phase + 0.01 * k))) for k in range(4)]
    counter = iter(range(10**9))
    row("temporal unwrap (steady state)", lambda: unwrapper.update(drift[next(counter) % 4], mask), [wrapped])

    grid = LensletLattice.array("square", 25.0, (40, 40), first_centre_px=(152.5, 24.5))
    reference_frame = spot_frame(grid, np.zeros(2))
    measured_frame = spot_frame(grid, np.array([0.7, -0.4]))
    centroider = Centroider.build(grid, reference_frame.shape)
    reference = centroider.measure(reference_frame)
    centres = grid.centres_xy()
    reconstructor = ModalReconstructor.for_circle(
        centres, tuple(centres.mean(axis=0)), 20 * 25.0, mode_list("noll", 15), reference.valid
    )

    def sh_frame() -> None:
        result = slopes(centroider.measure(measured_frame), reference, focal_length_um=5000.0, pixel_um=5.0)
        reconstructor.reconstruct(result.slopes_x, result.slopes_y)

    row("SH 40x40 centroids + 15-mode reconstruction", sh_frame, [measured_frame])
    # the station's processor (centroids, lit rule, slopes, cached 36-mode reconstructor) on a square
    # 40 x 40 array and on a hexagonal one of 46 rows of 40 (the same area): the hexagonal windows
    # are gathered one per lenslet
    for kind, shape in (("square", (40, 40)), ("hexagonal", (46, 40))):
        array = LensletLattice.array(kind, 25.0, shape, first_centre_px=(152.5, 24.5))
        setup = ShackHartmannSetup(focal_length_um=5000.0, pixel_um=5.5, wavelength_nm=632.8, lattice=kind,
                                   pitch_px=25.0, offset_px=(140.0, 12.0), grid_shape=shape,
                                   pupil_px=(640.0, 512.0, 480.0), min_intensity=1000.0)
        spots = spot_frame(array, np.array([0.7, -0.4]))
        processor = ShackHartmannProcessor(setup, reference_frame=spot_frame(array, np.zeros(2)))
        assert processor.process([spots]).valid
        row(f"SH processor, {kind} {shape[0]}x{shape[1]} (36 modes)", lambda p=processor, f=spots: p.process([f]),
            [spots])

    print(f"# bench_signal: {SIZE}x{SIZE} (SH 1280x1024), 1 thread, {n} runs, medians (p99) in ms")
    print()
    print("| stage | median ms | p99 ms | memory pass ms | median / pass |")
    print("|---|---:|---:|---:|---:|")
    for name, median, p99, memory in rows:
        print(f"| {name} | {median * 1e3:.2f} | {p99 * 1e3:.2f} | {memory * 1e3:.2f} | {median / memory:.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
