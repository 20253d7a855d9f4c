"""What a task sends back: plain frozen values (numbers, strings, tuples), nothing h5py or numpy.

A worker's result is pickled to the client; these types hold only built-in values, so they
travel cheaply and unpickle on a client of any numpy version.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace

from wavestack.recording.replay import ReplayedResult

#: The pipeline stages whose time a task adds up (seconds, from each outcome's ``timings_s``).
STAGES = ("phase", "aperture", "unwrap", "fit")


@dataclass(frozen=True)
class ResultRow:
    """One recomputed result (one row of the results table).

    Attributes
    ----------
    recording : str
        The recording's path as given.
    position : int
        The set's position in the recording (or the map's, for a polish campaign).
    index : int
        The station's set index (the map's index for a polish campaign).
    time_ns : int
        Host time of the set's first frame, ns since the Unix epoch (polish: the exposure time).
    frame_ids : tuple of int
    valid : bool
    reason : str
        Why the result is invalid ("" when valid).
    coefficients : tuple of float
        Zernike coefficients in ``units`` (empty when invalid).
    units : str
        "waves" (station) or "nm" (polish surface maps).
    residual_rms, residual_pv : float
        Fit residual, ``units`` (NaN when invalid).
    fitter, unwrap_path : str
    fitter_fallback : bool
    aperture_id : int
        The aperture's number within the recording's analysis, from 0 (-1 without one).
    aperture_changed : bool
    aperture_pixels : int
        Valid pixels of the aperture at full resolution (-1 without one).
    aperture_topology : str
    gram_condition, max_beltrami : float
        Fitter diagnostics (NaN when unknown).
    flips : int
        Inverted mesh triangles of a mapped fitter (-1 when unknown).
    difference_rms, residual_pv_difference : float
        Against the recorded result, waves (NaN when not compared).
    affected_by_damage : bool
        As :attr:`wavestack.recording.ReplayedResult.affected_by_damage`.
    """

    recording: str
    position: int
    index: int
    time_ns: int
    frame_ids: tuple[int, ...]
    valid: bool
    reason: str
    coefficients: tuple[float, ...]
    units: str
    residual_rms: float
    residual_pv: float
    fitter: str
    fitter_fallback: bool
    unwrap_path: str
    aperture_id: int
    aperture_changed: bool
    aperture_pixels: int
    aperture_topology: str
    gram_condition: float
    flips: int
    max_beltrami: float
    difference_rms: float
    residual_pv_difference: float
    affected_by_damage: bool

    @classmethod
    def column_names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))


@dataclass(frozen=True)
class SkippedItem:
    """A set (or map) that could not be read intact: position, station set index (-1 unknown), reason."""

    position: int
    index: int
    reason: str


@dataclass(frozen=True)
class TaskOutcome:
    """What one task gives back.

    Attributes
    ----------
    rows : tuple of ResultRow
    skipped : tuple of SkippedItem
    damage, notes : tuple of str
        The reader's damage report and notes after the task's reads.
    error : str
        Why nothing could be analysed ("" when something was).
    boundary_ok : bool or None
        For a task with ``check_next``: the continuing run adopted an aperture at ``stop``.
    stage_s : tuple of float
        Seconds spent per stage (:data:`STAGES`), summed over the task's sets.
    wall_s : float
        Seconds the task took on its worker.
    """

    rows: tuple[ResultRow, ...] = ()
    skipped: tuple[SkippedItem, ...] = ()
    damage: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    error: str = ""
    boundary_ok: bool | None = None
    stage_s: tuple[float, ...] = field(default=(0.0,) * len(STAGES))
    wall_s: float = 0.0


def station_row(recording: str, position: int, time_ns: int, item: ReplayedResult) -> ResultRow:
    """The row of one replayed station result."""
    p = item.processed
    valid_coefficients = p.coefficients_waves is not None and p.valid
    aperture = getattr(p, "aperture_record", None)
    diagnostics = getattr(p, "diagnostics", None)
    return ResultRow(
        recording=recording, position=position, index=item.index, time_ns=time_ns, frame_ids=item.frame_ids,
        valid=bool(p.valid), reason=p.reason or "",
        coefficients=tuple(float(c) for c in p.coefficients_waves) if valid_coefficients else (),
        units="waves", residual_rms=_real(p.residual_rms), residual_pv=_real(p.residual_pv),
        fitter=p.fitter_kind or "", fitter_fallback=bool(p.fitter_fallback), unwrap_path=p.unwrap_path or "",
        aperture_id=-1 if aperture is None or aperture.id is None else int(aperture.id),
        aperture_changed=bool(getattr(p, "aperture_changed", False)),
        aperture_pixels=-1 if aperture is None else int(aperture.valid_pixels),
        aperture_topology="" if aperture is None else str(aperture.topology),
        gram_condition=_real(None if diagnostics is None else diagnostics.gram_condition),
        flips=-1 if diagnostics is None or diagnostics.flips is None else int(diagnostics.flips),
        max_beltrami=_real(None if diagnostics is None else diagnostics.max_beltrami),
        difference_rms=_real(item.difference_rms), residual_pv_difference=_real(item.residual_pv_difference),
        affected_by_damage=bool(item.affected_by_damage))


def renumbered(row: ResultRow, aperture_offset: int, after_damage: bool) -> ResultRow:
    """``row`` of a later block: aperture ids counted from the recording's start, damage before it noted."""
    aperture_id = row.aperture_id + aperture_offset if row.aperture_id >= 0 else -1
    return replace(row, aperture_id=aperture_id, affected_by_damage=row.affected_by_damage or after_damage)


def _real(value: float | None) -> float:
    return math.nan if value is None else float(value)
