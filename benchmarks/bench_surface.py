"""Surface figures: accuracy against independent computations, cost per map, and the live station's cost.

Prints, in one run:

* accuracy: PVr on the bundled Zygo map against Evans' definition written out here; band RMS on
  square, fully measured data against the sinusoids' known power; power-law surfaces (2-D PSD
  ``f^-3``) on a rounded rectangle and an annulus, several seeds: the fitted slope's error and the
  band RMS against the surface's band content as the window weighs it and against the ensemble
  truth; the Gaussian filter's transmission inside the area;
* cost per map of each figure on the Zygo map (136k pixels);
* the live station (the default simulated station, psi path): per-result time with the figures
  off and on, in alternating blocks of one run, the figures computed on the station's thread
  exactly where a result is made (form, PVr and the verdict every result, the PSD every
  ``--spectra-every``-th, on at most ``--max-pixels`` of the fit grid's pixels).

Usage: ``.venv/bin/python benchmarks/bench_surface.py [--seeds 8] [--blocks 4] [--block 20]``.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import threading
import time
from contextlib import ExitStack
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from wavestack.config import load_station_config  # noqa: E402
from wavestack.pipeline import read_measured_map  # noqa: E402
from wavestack.pipeline.surface import (  # noqa: E402
    FormAnalyzer, RobustPVAnalyzer, SurfaceRequest, aperture_outline, aperture_window, filter_surface,
    measured_area, parse_areal_filter, parse_form_tolerance, slope_maps, surface_psd,
)
from wavestack.station import CycleRecord, Station, open_station_devices  # noqa: E402
from wavestack.station.surface_stage import SurfaceStage  # noqa: E402

DATA = Path(os.environ.get("WAVESTACK_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "pipeline" / "surface"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_robust_pv import _independent_pvr  # noqa: E402


def _timed(function, repeats: int = 7) -> float:
    function()
    times = []
    for _ in range(repeats):
        tick = time.perf_counter()
        function()
        times.append(time.perf_counter() - tick)
    return float(np.median(times)) * 1e3


def accuracy(seeds: int) -> None:
    data = read_measured_map(DATA / "zygo-dat" / "valid_zygo_dat_file.dat")
    valid = np.asarray(data.valid)
    pvr = RobustPVAnalyzer(measured_area(valid)).measure(data.map_nm).pvr
    print(f"PVr, Zygo map        {pvr:.4f} nm; written out: {_independent_pvr(data.map_nm, valid):.4f} nm "
          f"(ratio - 1 = {pvr / _independent_pvr(data.map_nm, valid) - 1:.2e}; target 1 %)")

    rows, cols = np.indices((256, 256)) * 0.2
    rng = np.random.default_rng(3)
    frequencies = [0.12, 0.21, 0.33, 0.47, 0.62, 0.8, 1.05, 1.3, 1.7, 2.1]
    amplitudes = rng.uniform(1.0, 5.0, len(frequencies))
    square = sum(a * np.sin(2 * np.pi * f * (cols * np.cos(t) + rows * np.sin(t)) + p) for f, a, t, p in
                 zip(frequencies, amplitudes, rng.uniform(0, np.pi, 10), rng.uniform(0, 2 * np.pi, 10)))
    expected = math.sqrt(sum(a * a for f, a in zip(frequencies, amplitudes) if 0.25 <= f <= 1.5) / 2)
    band = surface_psd(measured_area(np.ones((256, 256), bool)), square, 0.2).band_rms_nm(0.25, 1.5)
    print(f"band RMS, square     {band:.4f} nm against the sinusoids' {expected:.4f} nm "
          f"({100 * (band / expected - 1):+.2f} %; target 2 %)")

    n, pixel, low, high = 512, 0.1, 0.3, 3.0
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(n, pixel), np.fft.fftfreq(n, pixel)))
    radius = np.hypot(*(np.indices((n, n)) - 255.5))
    dx, dy = np.abs(np.indices((n, n))[1] - 255.5) - 210, np.abs(np.indices((n, n))[0] - 255.5) - 70
    masks = {"rounded rectangle": np.hypot(np.maximum(dx, 0), np.maximum(dy, 0)) <= 30,
             "annulus": (radius <= 240) & (radius >= 90)}
    analytic = math.sqrt(np.sum(np.where((f >= low) & (f <= high), np.where(f > 0, f, 1.0) ** -3.0, 0.0))
                         / (n * pixel) ** 2)
    for name, mask in masks.items():
        area, weights = measured_area(mask), aperture_window(aperture_outline(mask)) ** 2
        slopes, windowed, ensemble = [], [], []
        for seed in range(seeds):
            generator = np.random.default_rng(seed)
            scale = np.where(f > 0, np.where(f > 0, f, 1.0) ** -1.5, 0.0) / (n * pixel)
            coefficients = scale * (generator.normal(size=f.shape) + 1j * generator.normal(size=f.shape)) / np.sqrt(2)
            surface = np.real(np.fft.ifft2(coefficients)) * n * n * np.sqrt(2)
            psd = surface_psd(area, np.where(mask, surface, np.nan), pixel)
            passed = np.real(np.fft.ifft2(np.fft.fft2(surface) * ((f >= low) & (f <= high))))
            rms = psd.band_rms_nm(low, high)
            slopes.append(psd.power_law(low, high).slope + 3.0)
            windowed.append(rms / math.sqrt(np.sum(weights * passed**2) / np.sum(weights)) - 1)
            ensemble.append(rms / analytic - 1)
        print(f"power law, {name:17s} {seeds} seeds: slope error median {np.median(np.abs(slopes)):.3f}, max "
              f"{np.max(np.abs(slopes)):.3f} (target 0.05); band RMS against its windowed content median "
              f"{100 * np.median(np.abs(windowed)):.2f} %, max {100 * np.max(np.abs(windowed)):.2f} %; against the "
              f"ensemble {100 * np.median(np.abs(ensemble)):.2f} %, max {100 * np.max(np.abs(ensemble)):.2f} % "
              "(target 3 %)")

    disk = radius[56:456, 56:456] <= 190
    inside = radius[56:456, 56:456] <= 190 - 22
    grid_rows, grid_cols = np.indices(disk.shape) * 0.05
    for kind, wavelength, what in (("lp", 1 / 3.2, "stop"), ("lp", 12.0, "pass"), ("lp", 1.0, "cut-off"),
                                   ("hp", 30.0, "stop"), ("hp", 1 / 3.2, "pass")):
        wave = np.sin(2 * np.pi * (0.8 * grid_cols + 0.6 * grid_rows) / wavelength + 0.3)
        out = filter_surface(measured_area(disk), wave, 0.05, parse_areal_filter(f"{kind}:1"))
        gain = math.sqrt(np.sum(out[inside] ** 2) / np.sum(wave[inside] ** 2))
        print(f"filter {kind}:1 mm at {wavelength:7.4f} mm ({what:7s}) gain {gain:.6f} = {20 * math.log10(gain):7.2f} dB")


def costs() -> None:
    data = read_measured_map(DATA / "zygo-dat" / "valid_zygo_dat_file.dat")
    valid, pixel = np.asarray(data.valid), data.pixel_size_m * 1e3
    area = measured_area(valid)
    tick = time.perf_counter()
    form = FormAnalyzer(area)
    pvr = RobustPVAnalyzer(area)
    build = time.perf_counter() - tick
    print(f"per map, Zygo map ({area.pixels} px): analyzers built in {build:.2f} s; form "
          f"{_timed(lambda: form.figures(data.map_nm)):.1f} ms, PVr {_timed(lambda: pvr.measure(data.map_nm)):.1f} ms, "
          f"PSD {_timed(lambda: surface_psd(area, data.map_nm, pixel)):.1f} ms, slope (1 mm) "
          f"{_timed(lambda: slope_maps(area, data.map_nm, pixel, 1.0)):.1f} ms, filter bp:0.5,5 "
          f"{_timed(lambda: filter_surface(area, data.map_nm, pixel, parse_areal_filter('bp:0.5,5'))):.1f} ms "
          "(medians of 7)")


class _Alternating:
    """A result sink: warm-up, then blocks of results with the figures off and on, timed per result."""

    def __init__(self, stage: SurfaceStage, blocks: int, block: int, stop: threading.Event) -> None:
        self.stage, self.blocks, self.block, self.stop = stage, blocks, block, stop
        self.warmup = 0
        self.last: float | None = None
        self.intervals: dict[bool, list[float]] = {False: [], True: []}
        self.figure_ms: list[float] = []
        self.count = 0
        self.verdicts = 0

    def __call__(self, record: CycleRecord) -> None:
        result = record.result
        if self.warmup < 8:
            self.warmup += result.valid and not result.fitter_fallback
            self.last = time.perf_counter()
            return
        on = (self.count // self.block) % 2 == 1
        if on and record.waves is not None and result.valid:
            tick = time.perf_counter()
            figures = self.stage.measure(result.index, record.waves)
            self.figure_ms.append((time.perf_counter() - tick) * 1e3)
            self.verdicts += figures.verdict is not None
        now = time.perf_counter()
        if self.last is not None:
            self.intervals[on].append(now - self.last)
        self.last = now
        self.count += 1
        if self.count >= 2 * self.blocks * self.block:
            self.stop.set()


def live(blocks: int, block: int, max_pixels: int, spectra_every: int) -> None:
    config = load_station_config(None)
    request = SurfaceRequest(tolerance=parse_form_tolerance("3/2(0.5/0.2; RMSi < 0.1)"), psd=True,
                             slope_length_mm=2.0)
    # the default optic is 1024 px across the camera; call it a 100 mm part: 0.1 mm per camera pixel
    decimation = config.processing.fit_decimation
    stage = SurfaceStage(request, wavelength_nm=config.station.wavelength_nm, surface_factor=0.5,
                         pixel_mm=0.1 * decimation, max_pixels=max_pixels, spectra_every=spectra_every)
    stop = threading.Event()
    sink = _Alternating(stage, blocks, block, stop)
    with ExitStack() as stack:
        devices = open_station_devices(config, stack)
        station = Station(config, devices)
        stack.callback(station.close)
        station.run(stop=stop, on_result=sink, duration_s=600.0)
    off, on = (np.array(sink.intervals[k]) * 1e3 for k in (False, True))
    print(f"live station (psi path, load {os.getloadavg()[0]:.1f}): per-result time off {np.mean(off):.1f} ms "
          f"({off.size} results), on {np.mean(on):.1f} ms ({on.size}); added {100 * (np.mean(on) / np.mean(off) - 1):+.1f} %"
          f" (target <= 10 %); figures themselves median {np.median(sink.figure_ms):.2f} ms, mean "
          f"{np.mean(sink.figure_ms):.2f} ms = {100 * np.mean(sink.figure_ms) / np.mean(off):.1f} % of the off time "
          f"(max_pixels {max_pixels}, spectra every {spectra_every}); {sink.verdicts} verdicts")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--blocks", type=int, default=4)
    parser.add_argument("--block", type=int, default=20)
    parser.add_argument("--max-pixels", type=int, default=20000)
    parser.add_argument("--spectra-every", type=int, default=10)
    parser.add_argument("--skip", nargs="*", default=[], choices=("accuracy", "costs", "live"))
    args = parser.parse_args()
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} at the start")
    if "accuracy" not in args.skip:
        accuracy(args.seeds)
    if "costs" not in args.skip:
        costs()
    if "live" not in args.skip:
        live(args.blocks, args.block, args.max_pixels, args.spectra_every)


if __name__ == "__main__":
    main()
