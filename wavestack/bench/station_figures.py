"""The figures ``wavestack bench station`` reports, its targets, and their text and JSON forms."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

STAGES = ("phase", "aperture", "unwrap", "quality", "fit", "clip", "statistics")
TARGET_RESULTS_PER_S = 20.0  # carrier path
TARGET_P99_MS = 150.0  # carrier path
TARGET_NEW_MAP_S = 1.0
TARGET_OVERHEAD = 1.5


@dataclass(frozen=True)
class StationPathFigures:
    """What one path measured; ``*_ms`` are milliseconds per result, ``*_s`` seconds.

    ``path`` ("carrier" or "psi") and ``description`` (method, frame, carrier or steps, fitter)
    name it. ``results`` were measured after ``warmup_results`` (``warmup_s``) until the
    configured fitter of the first aperture was in use. ``results_per_s`` over the measured
    results, ``per_result_ms = 1000 / results_per_s``, latency percentiles from the first frame's
    arrival. ``stage_ms`` / ``stage_median_ms``: mean / median per stage in the station;
    ``alone_stage_ms``: mean per stage of the processor's ``process`` alone (``alone_runs`` calls,
    ``alone_process_ms`` per call); ``overhead_ratio = per_result_ms / sum(alone_stage_ms)``;
    ``outside_stages_ms = per_result_ms - sum(stage_ms)`` (truth comparison, PLC, waiting for a
    set), of which ``plc_io_ms`` (wall time in the PLC link's calls, ``plc_requests_per_result``
    Modbus requests).
    ``process_cpu_ms``: process CPU per result; ``simulator_cpu_ms``: ``camera`` (USB backend
    transfers, render included), ``render`` (the optic alone), ``piezo``, ``plc``;
    ``simulator_share = (camera + piezo + plc) / process_cpu_ms``; ``thread_cpu_ms``: per thread
    role ("native pools" are threads Python did not start: BLAS, OpenCV). ``set_arrival_ms``:
    median first-to-last frame arrival of a set (0 for carrier). ``frames_acquired`` /
    ``frames_dropped`` over the measured window. Aperture change: ``aperture_set_s`` (the
    simulator's own ``set_aperture``, not counted), ``aperture_detect_s`` and
    ``aperture_new_map_s`` from the change (None: not within the limit), and the number of
    ``aperture_changes`` the station reported (1 expected).
    """

    path: str
    description: str
    results: int
    warmup_results: int
    warmup_s: float
    results_per_s: float
    per_result_ms: float
    latency_p50_ms: float
    latency_p99_ms: float
    stage_ms: dict[str, float]
    outside_stages_ms: float
    plc_io_ms: float
    plc_requests_per_result: float
    stage_median_ms: dict[str, float]
    alone_stage_ms: dict[str, float]
    alone_process_ms: float
    alone_runs: int
    overhead_ratio: float
    process_cpu_ms: float
    simulator_cpu_ms: dict[str, float]
    simulator_share: float
    thread_cpu_ms: dict[str, float]
    set_arrival_ms: float
    frames_acquired: int
    frames_dropped: int
    aperture_set_s: float | None
    aperture_detect_s: float | None
    aperture_new_map_s: float | None
    aperture_changes: int


# ---------------------------------------------------------------------------------- output


@dataclass(frozen=True)
class MachineState:
    """The machine a benchmark ran on: CPUs, the 1-minute load average at the start, the BLAS threads."""

    cpus: int | None
    load_average_1min: float
    openblas_num_threads: str

    def to_json(self) -> dict[str, object]:
        return asdict(self)


def targets() -> dict[str, float]:
    """The targets the figures are marked against, by JSON name."""
    return {"carrier_results_per_s_min": TARGET_RESULTS_PER_S, "carrier_latency_p99_ms_max": TARGET_P99_MS,
            "aperture_new_map_s_max": TARGET_NEW_MAP_S, "overhead_ratio_max": TARGET_OVERHEAD}


def _json_ready(value: Any) -> Any:
    if isinstance(value, float):
        return value if np.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _json_ready(v) for k, v in value.items()}
    return value


def figures_json(figures: Sequence[StationPathFigures]) -> list[dict[str, Any]]:
    """The figures of each path as JSON-ready dicts (NaN becomes None)."""
    return [_json_ready(asdict(f)) for f in figures]


def _target(text: str, ok: bool) -> str:
    return f"target {text}: {'pass' if ok else 'MISS'}"


def _seconds(value: float | None) -> str:
    return "not within the limit" if value is None else f"{value:.2f} s"


def format_figures(source: str, figures: Sequence[StationPathFigures],
                   machine: MachineState | None = None) -> list[str]:
    """The figures as text lines, targets beside them (``machine``: see :func:`machine_state`)."""
    lines = [f"wavestack bench station: {source}"]
    if machine is not None:
        lines.append(f"machine: {machine.cpus} CPUs, load average {machine.load_average_1min:.2f} at the "
                     f"start, OPENBLAS_NUM_THREADS={machine.openblas_num_threads}")
    row = "{:<24}{:<48}{}".format
    for f in figures:
        carrier = f.path == "carrier"
        new_map_ok = f.aperture_new_map_s is not None and f.aperture_new_map_s <= TARGET_NEW_MAP_S
        lines += [
            "", f"== {f.path} path: {f.description}",
            f"   {f.results} results measured after a warm-up of {f.warmup_results} results ({f.warmup_s:.1f} s, "
            "until the configured fitter was in use); stage times are over the same results",
            row("results/s", f"{f.results_per_s:.1f}",
                _target(f">= {TARGET_RESULTS_PER_S:g}", f.results_per_s >= TARGET_RESULTS_PER_S) if carrier else ""),
            row("latency p50 / p99", f"{f.latency_p50_ms:.0f} / {f.latency_p99_ms:.0f} ms",
                _target(f"p99 <= {TARGET_P99_MS:g} ms", f.latency_p99_ms <= TARGET_P99_MS) if carrier else ""),
            row("per-result time", f"{f.per_result_ms:.1f} ms (1 / rate)", ""),
            row("set arrival", f"{f.set_arrival_ms:.1f} ms (first to last frame of a set, median)", ""),
            row("stage ms", "station mean / median | alone mean", ""),
            *(row(f"  {stage}", f"{f.stage_ms[stage]:.1f} / {f.stage_median_ms[stage]:.1f} | "
                                f"{f.alone_stage_ms[stage]:.1f}", "") for stage in STAGES),
            row("  sum of stages", f"{sum(f.stage_ms.values()):.1f} | {sum(f.alone_stage_ms.values()):.1f} "
                                   f"(alone: {f.alone_runs} runs on recorded sets)", ""),
            row("  process() alone", f"{f.alone_process_ms:.1f} ms per call", ""),
            row("outside the stages", f"{f.outside_stages_ms:.1f} ms per result (truth comparison, PLC, "
                                      "waiting for a set)", ""),
            row("  PLC I/O", f"{f.plc_io_ms:.1f} ms per result, {f.plc_requests_per_result:.1f} Modbus requests", ""),
            row("hidden overhead", f"{f.overhead_ratio:.2f} x (per-result time / alone stage sum)",
                _target(f"<= {TARGET_OVERHEAD:g}", f.overhead_ratio <= TARGET_OVERHEAD)),
            row("process CPU", f"{f.process_cpu_ms:.1f} ms per result "
                               f"({f.process_cpu_ms / f.per_result_ms:.2f} cores busy)", ""),
            row("simulator share", f"{100 * f.simulator_share:.0f} % of the process CPU", ""),
            "   simulator CPU ms per result (thread CPU inside the simulated devices; camera = USB transfers "
            "incl. render): " + ", ".join(f"{k} {v:.1f}" for k, v in f.simulator_cpu_ms.items()),
            "   CPU ms per result by thread: " + ", ".join(f"{k} {v:.1f}" for k, v in f.thread_cpu_ms.items()),
            row("frames", f"{f.frames_acquired} acquired, {f.frames_dropped} dropped", ""),
            row("aperture change", f"detected {_seconds(f.aperture_detect_s)}, new map "
                                   f"{_seconds(f.aperture_new_map_s)}", _target(f"<= {TARGET_NEW_MAP_S:g} s", new_map_ok)),
            f"   (the optic's own set_aperture took {_seconds(f.aperture_set_s)}, not counted; aperture changes "
            f"reported: {f.aperture_changes})",
        ]
    return lines
