"""``wavestack bench paper``: the seed paper's Tables 1-3 rebuilt on our implementation.

For every paper aperture (:mod:`wavestack.bench.paper_apertures`, 512 x 512 samples) and every fit
method (circle, qr, conformal, csf-qcm with cotangent and with graph weights; 36 Noll modes,
meshes of about 15k vertices) it measures:

* kappa(G), the coefficient noise gain, flips, max |mu| and the area-scale ratio s95/s5;
* setup (a), a *physical* truth: a random 36-term Zernike surface over the aperture's
  circumscribed circle scaled to PV 0.05 waves on the aperture (median of 5 seeds), a smooth
  surface with content beyond 36 modes (91 terms, amplitudes falling as 1/(n+1)^2, PV 0.05),
  and the first truth plus 0.001 waves RMS of white noise: RMS and PV of the reconstructed
  surface minus the noise-free truth;
* setup (b), a truth built in each method's own canonical basis and pulled back (what the
  paper appears to have done): every least-squares method reproduces it to rounding, so the
  table reports the largest error over all methods, once;
* for mapped methods, the change of the fitted basis between a 5k and a 15k mesh
  (``||H_5k - H_15k||_F / ||H_15k||_F`` on the same pixels);
* build times per stage.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass, field

import numpy as np
from numpy.typing import NDArray

from wavestack.bench.paper_apertures import PAPER_APERTURES
from wavestack.figures.paper_views import PaperViews, paper_views
from wavestack.pipeline import Aperture, Pupil, build_fitter, mode_list, zernike_basis
from wavestack.pipeline import MappingOptions, Samples, build_canonical_map, mapped_columns

logger = logging.getLogger(__name__)

MODES = 36
TRUTH_PV_WAVES = 0.05
NOISE_RMS_WAVES = 0.001
SEEDS = (1, 2, 3, 4, 5)
# (method, laplacian, angular balance); the unbalanced rows are the paper's method alone.
METHODS = (
    ("circle", "cotangent", False),
    ("qr", "cotangent", False),
    ("conformal", "cotangent", False),
    ("csf-qcm", "graph", False),
    ("csf-qcm", "cotangent", False),
    ("csf-qcm", "cotangent", True),
)

# The paper's own figures (Tables 1-3), for the side-by-side columns.
PAPER_KAPPA = {"butterfly": (901.55, 6.61), "rounded-rectangle": (188.86, 5.51),
               "annulus-circular-hole": (162.45, 7.76)}
PAPER_RMS = {"butterfly": (0.0191, 0.0030), "rounded-rectangle": (0.0390, 0.0029),
             "annulus-circular-hole": (0.0263, 0.0031)}
PAPER_TOTAL_S = {"butterfly": 2.80, "rounded-rectangle": 3.00, "annulus-circular-hole": 3.65}


@dataclass(frozen=True)
class PaperRow:
    """One aperture and method of the benchmark (errors in waves, times in seconds)."""

    aperture: str
    method: str
    laplacian: str
    angular_balance: bool
    kappa: float
    noise_gain: float
    flips: int | None
    max_beltrami: float | None
    s95_over_s5: float | None
    r_in: float | None
    physical_rms: float
    physical_pv: float
    smooth_rms: float
    smooth_pv: float
    noisy_rms: float
    canonical_rms: float
    basis_change: float | None
    build_seconds: float
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def label(self) -> str:
        """Method name with its weights where they matter."""
        return self.label_of(self.method, self.laplacian, self.angular_balance)

    @staticmethod
    def label_of(method: str, laplacian: str, angular_balance: bool) -> str:
        """``'csf-qcm (cotangent, balanced)'``: a method's name with its weights where they matter."""
        if method != "csf-qcm":
            return method
        return f"csf-qcm ({laplacian}{', balanced' if angular_balance else ''})"


def _truths(aperture: Aperture, seed: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The physical truth and the smooth 91-term truth on the aperture's pixels (PV 0.05)."""
    cx, cy, radius = aperture.enclosing_circle()
    rows, cols = np.nonzero(aperture.mask)
    x, y = (cols - cx) / radius, (cy - rows) / radius
    rng = np.random.default_rng(seed)
    physical = zernike_basis(mode_list("noll", MODES), x, y) @ rng.normal(size=MODES)
    modes = mode_list("noll", 91)
    amplitudes = np.array([1.0 / (n + 1) ** 2 for n, _ in modes]) * rng.normal(size=91)
    smooth = zernike_basis(modes, x, y) @ amplitudes
    return (TRUTH_PV_WAVES * physical / np.ptp(physical),
            TRUTH_PV_WAVES * smooth / np.ptp(smooth))


def _reconstruction(fitter, aperture: Aperture, values: NDArray[np.float64]) -> NDArray[np.float64]:
    """The fitted surface of ``values`` (on the aperture's pixels), on the same pixels."""
    rows, cols = np.nonzero(aperture.mask)
    frame = np.full(aperture.shape, np.nan)
    frame[rows, cols] = values
    return fitter.surface(fitter.fit(frame).coefficients)[rows, cols]


def _fit_error(fitter, aperture: Aperture, values: NDArray[np.float64], truth: NDArray[np.float64]) -> tuple[float, float]:
    error = _reconstruction(fitter, aperture, values) - truth
    return float(np.sqrt(np.mean(error**2))), float(np.ptp(error))


def _basis_change(aperture: Aperture, method: str, laplacian: str, balance: bool) -> float:
    rows, cols = np.nonzero(aperture.mask)
    samples = Samples(rows * aperture.shape[1] + cols, rows, cols, cols * 0.0, rows * 0.0, 0)
    modes = mode_list("noll", MODES)
    coarse, fine = (
        mapped_columns(build_canonical_map(aperture, method, MappingOptions(laplacian, vertices, balance)), samples, modes)
        for vertices in (5000, 15000)
    )
    return float(np.linalg.norm(coarse - fine) / np.linalg.norm(fine))


@dataclass(frozen=True, eq=False)
class PaperCase:
    """A row of the benchmark and, when asked for, what its figures show.

    Attributes
    ----------
    row : PaperRow
    views : PaperViews or None
        The fitter's map, Gram matrix and the first seed's truth and error (``bench paper --plots``).
    """

    row: PaperRow
    views: PaperViews | None = None


def benchmark_row(name: str, method: str, laplacian: str, balance: bool, size: int = 512) -> PaperRow:
    """Measure one aperture with one method (see the module docstring)."""
    return benchmark_case(name, method, laplacian, balance, size).row


def benchmark_case(name: str, method: str, laplacian: str, balance: bool, size: int = 512, *,
                   keep_views: bool = False) -> PaperCase:
    """Measure one aperture with one method; with ``keep_views``, keep what the figures show.

    Parameters
    ----------
    name : str
        A key of :data:`PAPER_APERTURES`.
    method, laplacian : str
    balance : bool
        Angular balance of the CSF-QCM map.
    size : int
        Samples across the aperture grid (the paper's 512).
    keep_views : bool
        Also return :class:`PaperViews` (maps of the aperture's size, the Gram matrix, the mesh).
    """
    aperture = Aperture.from_mask(PAPER_APERTURES[name](size))
    started = time.perf_counter()
    fitter = build_fitter(
        aperture, method=method, modes=MODES, dtype=np.float64, laplacian=laplacian,
        angular_balance=balance,
    )
    build_seconds = time.perf_counter() - started
    d = fitter.diagnostics
    physical, smooth, noisy = [], [], []
    views = None
    for seed in SEEDS:
        truth, smooth_truth = _truths(aperture, seed)
        physical.append(_fit_error(fitter, aperture, truth, truth))
        if keep_views and views is None:
            label = PaperRow.label_of(method, laplacian, balance)
            views = paper_views(name, label, aperture, fitter, truth, _reconstruction(fitter, aperture, truth))
        smooth.append(_fit_error(fitter, aperture, smooth_truth, smooth_truth))
        noise = np.random.default_rng(100 + seed).normal(0, NOISE_RMS_WAVES, truth.size)
        noisy.append(_fit_error(fitter, aperture, truth + noise, truth)[0])
    own = fitter.surface(np.random.default_rng(7).normal(0, 0.01, MODES))
    rows, cols = np.nonzero(aperture.mask)
    canonical_rms = _fit_error(fitter, aperture, own[rows, cols], own[rows, cols])[0]
    mapped = method in ("conformal", "csf-qcm")
    return PaperCase(PaperRow(
        aperture=name,
        method=method,
        laplacian=laplacian,
        angular_balance=balance,
        kappa=d.gram_condition,
        noise_gain=d.noise_gain,
        flips=d.flips,
        max_beltrami=d.max_beltrami,
        s95_over_s5=(d.area_scale_p95 / d.area_scale_p5) if mapped else None,
        r_in=d.r_in,
        physical_rms=float(np.median([e[0] for e in physical])),
        physical_pv=float(np.median([e[1] for e in physical])),
        smooth_rms=float(np.median([e[0] for e in smooth])),
        smooth_pv=float(np.median([e[1] for e in smooth])),
        noisy_rms=float(np.median(noisy)),
        canonical_rms=canonical_rms,
        basis_change=_basis_change(aperture, method, laplacian, balance) if mapped else None,
        build_seconds=build_seconds,
        timings={k: float(v) for k, v in d.timings.items()},
    ), views)


def run_paper_benchmark(apertures: tuple[str, ...] | None = None, size: int = 512) -> list[PaperRow]:
    """Every aperture with every method; returns the rows in table order."""
    return [case.row for case in run_paper_cases(apertures, size)]


def run_paper_cases(apertures: tuple[str, ...] | None = None, size: int = 512, *,
                    keep_views: bool = False) -> list[PaperCase]:
    """Every aperture with every method, in table order; with ``keep_views``, what the figures show.
    """
    cases = []
    for name in apertures or tuple(PAPER_APERTURES):
        for method, laplacian, balance in METHODS:
            logger.info("bench paper: %s, %s (%s, balance %s)", name, method, laplacian, balance)
            cases.append(benchmark_case(name, method, laplacian, balance, size, keep_views=keep_views))
    return cases


def _number(value: float | None, digits: str = ".3g") -> str:
    return "-" if value is None else format(value, digits)


def format_markdown(rows: list[PaperRow]) -> str:
    """The benchmark as Markdown tables, with the paper's figures beside ours."""
    lines = [
        f"Setup (a): physical truth, random {MODES}-term Zernike over the circumscribed circle, "
        f"PV {TRUTH_PV_WAVES} waves, median of {len(SEEDS)} seeds; smooth: 91 terms; noisy: "
        f"+{NOISE_RMS_WAVES} waves RMS white noise. Errors in waves.",
        "",
        "| aperture | method | kappa(G) | noise gain | flips | max mu | s95/s5 | RMS (a) | PV (a) "
        "| RMS smooth | RMS noisy | basis change 5k/15k | build s |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r.aperture} | {r.label} | {_number(r.kappa, '.4g')} | {_number(r.noise_gain)} | "
            f"{_number(r.flips, 'd')} | {_number(r.max_beltrami)} | {_number(r.s95_over_s5)} | "
            f"{r.physical_rms:.2e} | {r.physical_pv:.2e} | {r.smooth_rms:.2e} | {r.noisy_rms:.2e} | "
            f"{'-' if r.basis_change is None else f'{100 * r.basis_change:.2f} %'} | {r.build_seconds:.2f} |"
        )
    canonical = max(r.canonical_rms for r in rows)
    lines += [
        "",
        f"Setup (b), truth built in each method's own basis: largest fit error over all rows "
        f"{canonical:.1e} waves RMS (every least-squares method is exact on its own basis).",
        "",
        "| aperture | paper kappa: baseline / CSF-QCM | ours: conformal / csf-qcm graph (paper's) / "
        "csf-qcm balanced (default) | paper RMS: baseline / CSF-QCM | ours (a): conformal / graph / "
        "balanced | paper total s | ours build s (balanced) |",
        "|---|---|---|---|---|---:|---:|",
    ]
    for name, (paper_base, paper_qcm) in PAPER_KAPPA.items():
        mine = {r.label: r for r in rows if r.aperture == name}
        if not {"conformal", "csf-qcm (graph)", "csf-qcm (cotangent, balanced)"} <= set(mine):
            continue
        conf, paper, ours = mine["conformal"], mine["csf-qcm (graph)"], mine["csf-qcm (cotangent, balanced)"]
        lines.append(
            f"| {name} | {paper_base} / {paper_qcm} | {conf.kappa:.4g} / {paper.kappa:.4g} / "
            f"{ours.kappa:.4g} | {PAPER_RMS[name][0]} / {PAPER_RMS[name][1]} | "
            f"{conf.physical_rms:.2e} / {paper.physical_rms:.2e} / {ours.physical_rms:.2e} | "
            f"{PAPER_TOTAL_S[name]} | {ours.build_seconds:.2f} |"
        )
    return "\n".join(lines)


def rows_as_json(rows: list[PaperRow]) -> list[dict[str, object]]:
    """JSON-ready rows."""
    return [asdict(r) | {"label": r.label} for r in rows]
