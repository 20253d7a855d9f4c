"""From a trusted measurement to a checked job: dwell, machine program, predicted residual, job file.

:func:`plan_job` is pure computation (no I/O): the configured solver gives the dwell map
(:func:`~wavestack.pipeline.polishing.solve_dwell_fft`, RIFTA, or the bounded least squares of
:func:`~wavestack.pipeline.polishing.solve_dwell_lsq`); the machine program is planned from it along
the configured path and checked against the machine's limits (:func:`plan_program`,
:func:`check_program`). A solver that inverts its filter as far as the residual allows can ask
for more dwell than the machine takes (on a residual that is mostly fine structure and noise, the
least-RMS inverse filter gives an oscillating dwell of hours with a huge piston): the plan then
tries gentler solutions in turn (:data:`GENTLER`: RIFTA's threshold chosen with a larger residual
tolerance, or more damping of the least squares) until the program fits the machine's limits and
the job's removal depth, and refuses with every reason when none does (:class:`NoFittingJob`).
The prediction is made from what the machine will *execute* -- the
program's own dwell map, convolved with the host's TIF -- not from the solver's ideal map, so the
predicted residual is the one the measured residual should be compared with. :func:`job_file_of`
then makes the self-describing job file value of the program.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Final

import numpy as np
from numpy.typing import NDArray

from wavestack.config.polishing import PolishingSettings, TifSettings
from wavestack.drivers.plc import JobFile
from wavestack.pipeline.polishing import (
    DwellSolution,
    GridFrame,
    MachineLimits,
    MachineProgram,
    ProgramRejected,
    ToolInfluence,
    check_program,
    plan_program,
    removal_nm,
    residual_after,
    solve_dwell_bounded,
    solve_dwell_fft,
    solve_dwell_lsq,
)
from wavestack.polish.floor import JobFloor, job_floor
from wavestack.polish.measurement import Measurement

logger = logging.getLogger(__name__)

__all__ = ["GENTLER", "NoFittingJob", "PlannedJob", "host_tif", "job_file_of", "machine_limits", "lattice_points", "plan_job"]


#: The solvers' settings tried in turn, gentlest last: ``rms_tolerance`` of the FFT solver (the
#: residual it may leave above its best, as a fraction of the input RMS), ``damping`` of the
#: least squares, and for the bounded solver the share of the job's limits (total dwell, removal
#: depth) it is given: it keeps within them itself, so only the program's own additions (the feed
#: floor, the lattice's sampling) can push a job over, and a smaller share makes room for them.
GENTLER: Final = {"fft": (0.02, 0.05, 0.1, 0.2, 0.4), "lsq": (0.0, 1e-3, 1e-2, 1e-1, 1.0),
                  "bounded": (0.95, 0.8, 0.6, 0.4)}


class NoFittingJob(ValueError):
    """No solution of the ladder fits the machine and the job limits; the message gives each reason."""


@dataclass(frozen=True, eq=False)
class PlannedJob:
    """A job ready to hand off.

    Attributes
    ----------
    solution : DwellSolution
        The solver's answer (its ideal dwell and residual).
    program : MachineProgram
        What the machine will execute.
    dwell_s : ndarray (H, W)
        The program's dwell map on the grid, s.
    removal_nm : ndarray (H, W)
        The host TIF convolved with ``dwell_s``, nm.
    residual_nm : ndarray (H, W)
        Predicted surface after the job, nm, NaN outside the aperture, piston removed.
    predicted_rms_nm, predicted_pv_nm : float
    solve_s : float
        Seconds the solver and planner took (every attempt).
    gentleness : float
        The setting of :data:`GENTLER` the job was solved with.
    floor : JobFloor or None
        What the measurement after the job should show (:mod:`~wavestack.polish.floor`).
    """

    solution: DwellSolution
    program: MachineProgram
    dwell_s: NDArray[np.float64]
    removal_nm: NDArray[np.float64]
    residual_nm: NDArray[np.float64]
    predicted_rms_nm: float
    predicted_pv_nm: float
    solve_s: float
    gentleness: float = 0.0
    floor: JobFloor | None = None


def host_tif(settings: TifSettings, pixel_mm: float, base: Path | None = None) -> ToolInfluence:
    """The host's TIF model from ``[polishing.tif]`` (a ``map`` file relative to ``base``)."""
    if settings.kind == "gaussian":
        return ToolInfluence.gaussian(settings.fwhm_mm, settings.peak_rate_nm_s, pixel_mm)
    assert settings.file is not None  # TifSettings requires it for kind = "map"
    path = Path(settings.file)
    if base is not None and not path.is_absolute():
        path = base / path
    return ToolInfluence.from_map(np.load(path, allow_pickle=False), pixel_mm)


def lattice_points(shape: tuple[int, int], step_px: int) -> NDArray[np.intp]:
    """(K, 2) (row, col) pixels every ``step_px`` pixels each way, centred on the grid.

    Example
    -------
    >>> lattice_points((5, 5), 2).tolist()
    [[0, 0], [0, 2], [0, 4], [2, 0], [2, 2], [2, 4], [4, 0], [4, 2], [4, 4]]
    """
    axes = [np.arange((n - 1) // 2 % step_px, n, step_px) for n in shape]
    rows, cols = np.meshgrid(*axes, indexing="ij")
    return np.column_stack([rows.ravel(), cols.ravel()]).astype(np.intp)


def machine_limits(settings: PolishingSettings) -> MachineLimits:
    """The host's machine limits from ``[polishing.machine]`` and ``max_total_dwell_s``."""
    machine = settings.machine
    return MachineLimits(max_feed_mm_s=machine.max_feed_mm_s, max_accel_mm_s2=machine.max_accel_mm_s2,
                         travel_x_mm=machine.travel_x_mm, travel_y_mm=machine.travel_y_mm,
                         max_dwell_per_point_s=machine.max_dwell_per_point_s,
                         max_total_dwell_s=settings.max_total_dwell_s)


def _solve(measurement: Measurement, tif: ToolInfluence, settings: PolishingSettings, kind: str,
           gentleness: float) -> DwellSolution:
    surface, mask = measurement.surface_nm, measurement.mask
    if kind == "fft":
        return solve_dwell_fft(surface, mask, tif, rms_tolerance=gentleness)
    if kind == "lsq":  # one dwell point per program lattice point: the matrix stays within its budget
        return solve_dwell_lsq(surface, mask, tif, points_px=lattice_points(mask.shape, settings.machine.step_px),
                               max_dwell_s=settings.machine.max_dwell_per_point_s, damping=gentleness)
    if kind == "bounded":  # a program point gathers the step x step pixels around it
        return solve_dwell_bounded(surface, mask, tif,
                                   max_dwell_s=settings.machine.max_dwell_per_point_s / settings.machine.step_px**2,
                                   max_total_dwell_s=settings.max_total_dwell_s * gentleness,
                                   max_removal_nm=settings.max_removal_nm_per_run * gentleness)
    raise ValueError(f"solver: expected 'fft', 'lsq' or 'bounded', got {kind!r}")


#: A checked program with its prediction: program, executed dwell (s), removal (nm), residual (nm), RMS, PV (nm).
_Candidate = tuple[MachineProgram, NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float, float]


def _within_point_limit(dwell_s: NDArray[np.float64], settings: PolishingSettings) -> NDArray[np.float64]:
    """The dwell map with every pixel at most ``max_dwell_per_point_s / step_px**2`` s.

    A program point sums the dwell of the ``step_px x step_px`` pixels around it, so this cap keeps
    each point within the machine's per-point limit. The FFT solver has no bound of its own: on
    a measured map it asks for its longest dwell at the edge of the dwell grid, outside the clear
    aperture (the extension's high ground), where a run of the Zygo campaign asked 64-141 s
    against a 60 s limit and no job fitted. Clipping is a projection onto the feasible set: the
    prediction is then made from the executed program (below), so it stays honest, and the loop
    judges the clipped job by its predicted gain like any other.
    """
    cap = settings.machine.max_dwell_per_point_s / settings.machine.step_px**2
    return np.minimum(dwell_s, cap)


def plan_job(measurement: Measurement, tif: ToolInfluence, settings: PolishingSettings, *,
             solver: str | None = None) -> PlannedJob:
    """Solve, plan and check one job for ``measurement``, gentler until it fits (module notes).

    Parameters
    ----------
    measurement : Measurement
    tif : ToolInfluence
        The host's model.
    settings : PolishingSettings
    solver : {"fft", "lsq", "bounded"}, optional
        Overrides ``settings.solver``.

    Raises
    ------
    NoFittingJob
        No solution of the ladder fits the limits.
    ValueError
        A solver that refuses its input.
    """
    tick = time.perf_counter()
    kind = solver or settings.solver
    if kind not in GENTLER:
        raise ValueError(f"solver: expected 'fft', 'lsq' or 'bounded', got {kind!r}")
    frame = GridFrame(shape=measurement.mask.shape, pixel_mm=settings.pixel_mm)
    limits = machine_limits(settings)
    refusals: list[str] = []
    solutions: dict[float, DwellSolution] = {}
    for clipped in (False, True):  # clipped to the per-point limit only when no solution fits as it is
        for gentleness in GENTLER[kind]:
            if gentleness not in solutions:
                solutions[gentleness] = _solve(measurement, tif, settings, kind, gentleness)
            tried = _program_for(solutions[gentleness], measurement, tif, settings, frame, limits, clipped=clipped)
            label = f"{gentleness:g}{' clipped' if clipped else ''}"
            if isinstance(tried, str):
                refusals.append(f"{label}: {tried}")
                continue
            if refusals:
                logger.info("job planned with %s %s after %d other tries: %s", kind, label, len(refusals),
                            "; ".join(refusals))
            program, executed, removal, residual, rms, pv = tried
            points = np.column_stack(frame.to_px(program.x_mm, program.y_mm))
            floor = job_floor(executed, rms, measurement.mask, tif, points_px=points, points_dwell_s=program.dwell_s,
                              rate_uncertainty=settings.tif_rate_uncertainty,
                              width_uncertainty=settings.tif_width_uncertainty,
                              efficiency_spread=settings.efficiency_spread,
                              process_noise_nm=settings.process_noise_nm,
                              measurement_noise_nm=measurement.noise_rms_nm)
            return PlannedJob(solutions[gentleness], program, executed, removal, residual, rms, pv,
                              time.perf_counter() - tick, gentleness, floor)
    raise NoFittingJob(f"no {kind} job fits the limits ({len(refusals)} tried): " + "; ".join(refusals))


def _program_for(solution: DwellSolution, measurement: Measurement, tif: ToolInfluence, settings: PolishingSettings,
                 frame: GridFrame, limits: MachineLimits, *, clipped: bool) -> _Candidate | str:
    """The checked program of one solution and its prediction, or why it cannot be sent.

    A clipped solution is taken only if it predicts a lower RMS than the measurement's: clipping
    the most aggressive solution can leave a figure worse than the one it started from.
    """
    dwell = _within_point_limit(solution.dwell_s, settings) if clipped else solution.dwell_s
    try:
        program = plan_program(dwell, frame, limits, path=settings.machine.path, step_px=settings.machine.step_px)
        check_program(program, limits)
    except ProgramRejected as error:
        return str(error)
    executed = np.asarray(program.dwell_map(frame), dtype=np.float64)
    removal = np.asarray(removal_nm(executed, tif), dtype=np.float64)
    deepest = float(removal.max(initial=0.0))
    if deepest > settings.max_removal_nm_per_run:
        return f"removal {deepest:.0f} nm deep > max_removal_nm_per_run = {settings.max_removal_nm_per_run:g}"
    residual, rms, pv = residual_after(measurement.surface_nm, measurement.mask, removal)
    if clipped and not rms < measurement.rms_nm:
        return f"clipped to the per-point limit it predicts {rms:.3g} nm, no better than {measurement.rms_nm:.3g} nm"
    return program, executed, removal, np.asarray(residual, dtype=np.float64), float(rms), float(pv)


def job_file_of(job: PlannedJob, job_id: int, tif: ToolInfluence, aperture: dict[str, object],
                pixel_mm: float) -> JobFile:
    """The job file value of a planned job (the driver writes it)."""
    program = job.program
    return JobFile(job_id=job_id, x_mm=np.asarray(program.x_mm, dtype=np.float64),
                   y_mm=np.asarray(program.y_mm, dtype=np.float64), dwell_s=np.asarray(program.dwell_s, np.float64),
                   feed_mm_s=np.asarray(program.feed_mm_s, dtype=np.float64), pixel_mm=pixel_mm,
                   tif=tif.as_dict(), aperture=dict(aperture),
                   created_utc=datetime.now(timezone.utc).isoformat())
