"""One polishing run as a value: what was measured, predicted, sent and measured again.

A run's row is made when its job is handed off (:func:`run_started`: before, predicted, the job)
and completed when the next measurement comes in or the loop stops (:func:`run_finished`); the
recording writes it at both moments, so a run interrupted while the machine polishes is on disk
with everything but its result. :meth:`RunRecord.to_json` is the ``--json`` line;
:func:`run_line` the terminal's; :class:`RunMaps` the run's maps, as its figure draws them.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np
from numpy.typing import NDArray

__all__ = ["RunMaps", "RunRecord", "run_finished", "run_line", "run_started"]

_NAN = float("nan")


@dataclass(frozen=True)
class RunRecord:
    """One run of the loop (nm of surface; s; NaN where not known yet).

    Attributes
    ----------
    run : int
        Counted from 1.
    job_id : int
    rms_before_nm, pv_before_nm, noise_before_nm : float
        The measurement the job was computed from.
    predicted_rms_nm, predicted_pv_nm : float
        The residual the solver predicts for the program the machine executes.
    measured_rms_nm, measured_pv_nm : float
        The measurement after the job.
    convergence_ratio : float
        ``rms_before / measured_rms`` (> 1: the run improved the surface).
    predicted_ratio : float
        ``rms_before / predicted_rms``.
    total_dwell_s : float
        Dwell of the program sent.
    points : int
        Dwell points of the program.
    job_crc32 : int
        CRC-32 of the job file as written.
    machine_state : str
        The machine's last state for the job (``DONE``, ``ABORTED``, ...), empty until known.
    machine_reason : str
        The machine's reason code name, empty if none.
    points_done : int
        Points the machine reported done (-1 until known).
    started_unix_s : float
        When the job was handed off (``time.time()``).
    solve_s, run_s : float
        Seconds spent in the solver; wall-clock seconds from the measurement before to the one after.
    floor_nm : float
        What the measurement after the job should show: the predicted residual with the machine's
        model errors and the noise in quadrature (:mod:`~wavestack.polish.floor`).
    """

    run: int
    job_id: int
    rms_before_nm: float
    pv_before_nm: float
    noise_before_nm: float
    predicted_rms_nm: float
    predicted_pv_nm: float
    total_dwell_s: float
    points: int
    job_crc32: int
    started_unix_s: float
    solve_s: float
    measured_rms_nm: float = _NAN
    measured_pv_nm: float = _NAN
    convergence_ratio: float = _NAN
    predicted_ratio: float = _NAN
    machine_state: str = ""
    machine_reason: str = ""
    points_done: int = -1
    run_s: float = _NAN
    floor_nm: float = _NAN

    def to_json(self) -> dict[str, object]:
        """``{"type": "run", ...}`` with every field (NaN as null)."""
        return {"type": "run", **{k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                                  for k, v in asdict(self).items()}}


@dataclass(frozen=True, eq=False)
class RunMaps:
    """The maps of one run (H, W), NaN outside the aperture.

    Attributes
    ----------
    measured_nm : ndarray
        The surface the job was computed from, nm.
    dwell_s : ndarray
        The dwell map (0 outside the dwell grid), s per point.
    predicted_residual_nm : ndarray
        What the solver predicts the job leaves, nm.
    measured_residual_nm : ndarray or None
        The measurement after the job (None: not measured).
    """

    measured_nm: NDArray[np.floating]
    dwell_s: NDArray[np.floating]
    predicted_residual_nm: NDArray[np.floating]
    measured_residual_nm: NDArray[np.floating] | None


def run_started(run: int, job_id: int, *, rms_before_nm: float, pv_before_nm: float, noise_before_nm: float,
                predicted_rms_nm: float, predicted_pv_nm: float, total_dwell_s: float, points: int, job_crc32: int,
                started_unix_s: float, solve_s: float, floor_nm: float = _NAN) -> RunRecord:
    """The row of a run whose job was just handed off.

    Example
    -------
    >>> row = run_started(1, 7, rms_before_nm=40.0, pv_before_nm=200.0, noise_before_nm=0.2, predicted_rms_nm=4.0,
    ...                   predicted_pv_nm=30.0, total_dwell_s=900.0, points=4000, job_crc32=1, started_unix_s=0.0,
    ...                   solve_s=1.0)
    >>> row.predicted_ratio
    10.0
    """
    ratio = rms_before_nm / predicted_rms_nm if predicted_rms_nm > 0 else math.inf
    return RunRecord(run, job_id, rms_before_nm, pv_before_nm, noise_before_nm, predicted_rms_nm, predicted_pv_nm,
                     total_dwell_s, points, job_crc32, started_unix_s, solve_s, predicted_ratio=ratio,
                     floor_nm=floor_nm)


def run_finished(row: RunRecord, *, measured_rms_nm: float = _NAN, measured_pv_nm: float = _NAN,
                 machine_state: str, machine_reason: str = "", points_done: int, run_s: float) -> RunRecord:
    """The row completed with the machine's end and, when the loop measured again, the result.

    Example
    -------
    >>> row = run_started(1, 7, rms_before_nm=40.0, pv_before_nm=200.0, noise_before_nm=0.2, predicted_rms_nm=4.0,
    ...                   predicted_pv_nm=30.0, total_dwell_s=900.0, points=4000, job_crc32=1, started_unix_s=0.0,
    ...                   solve_s=1.0)
    >>> run_finished(row, measured_rms_nm=5.0, machine_state="DONE", points_done=4000, run_s=60.0).convergence_ratio
    8.0
    """
    ratio = row.rms_before_nm / measured_rms_nm if measured_rms_nm > 0 else _NAN
    return replace(row, measured_rms_nm=measured_rms_nm, measured_pv_nm=measured_pv_nm, convergence_ratio=ratio,
                   machine_state=machine_state, machine_reason=machine_reason, points_done=points_done, run_s=run_s)


def run_line(row: RunRecord) -> str:
    """One terminal line per run.

    Example
    -------
    >>> row = run_started(1, 7, rms_before_nm=40.0, pv_before_nm=200.0, noise_before_nm=0.2, predicted_rms_nm=4.0,
    ...                   predicted_pv_nm=30.0, total_dwell_s=900.0, points=4000, job_crc32=1, started_unix_s=0.0,
    ...                   solve_s=1.0)
    >>> run_line(row).split(":")[0]
    'run 1 (job 7)'
    """
    measured = (f"measured {row.measured_rms_nm:.2f} / {row.measured_pv_nm:.1f} nm, ratio {row.convergence_ratio:.2f}"
                if math.isfinite(row.measured_rms_nm) else "measured -")
    state = f"; machine {row.machine_state} {row.points_done}/{row.points}" if row.machine_state else ""
    return (f"run {row.run} (job {row.job_id}): RMS/PV before {row.rms_before_nm:.2f} / {row.pv_before_nm:.1f} nm, "
            f"predicted {row.predicted_rms_nm:.2f} / {row.predicted_pv_nm:.1f} nm, floor {row.floor_nm:.2f} nm, "
            f"{measured}; "
            f"dwell {row.total_dwell_s:.0f} s{state}")
