"""The station's maps as a loop sees them: a sink that hands N fresh maps in a row to a waiting measurement.

The station runs on its own thread for the whole of a loop (so the PLC heartbeat never pauses,
whether the loop measures, solves or waits for a machine) and gives every
:class:`~wavestack.station.cycle.CycleRecord` to a :class:`LiveMaps`. The sink keeps only what
is asked for: between measurements it notes the last PLC status and drops the maps. A measurement
(:meth:`LiveMaps.collect`, or :meth:`LiveMaps.average` for their mean) asks for ``count`` valid
maps in a row exposed after a given time (a machine's done, a platform on target); an invalid
result empties the window (the maps on either side of a glitch are not averaged together), and
the measurement gives up, untrusted, after ``max_results`` results, at its deadline, or when the
station stops.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.station.cycle import CycleRecord
from wavestack.station.plc_status import Heartbeat

__all__ = ["LiveMaps", "MapSample", "UntrustedMeasurement", "sample_of"]


class UntrustedMeasurement(ValueError):
    """A measurement a loop must not act on (no job, no move); the message says why."""


@dataclass(frozen=True, eq=False)
class MapSample:
    """One live result as the measurement sees it.

    Attributes
    ----------
    waves : ndarray (H, W) or None
        The unwrapped wavefront, waves, NaN outside the aperture (None: the result had none).
    valid : bool
    reason : str or None
        Why the result is invalid.
    aperture_id : int or None
        The station's aperture id of the result.
    exposure_time_ns : int
        Host time of the set's first frame (``time.time_ns``).
    """

    waves: NDArray[np.floating] | None
    valid: bool
    reason: str | None
    aperture_id: int | None
    exposure_time_ns: int


def sample_of(record: CycleRecord) -> MapSample:
    """The measurement's view of one cycle (pure)."""
    result = record.result
    return MapSample(record.waves, bool(result.valid and record.waves is not None), result.reason,
                     result.aperture.id if result.aperture is not None else None, result.exposure_time_ns)


@dataclass
class _Request:
    count: int
    max_results: int
    not_before_ns: int
    window: list[MapSample]
    looked: int = 0
    last_reason: str | None = None


class LiveMaps:
    """A thread-safe sink for the station's records (module notes).

    Example
    -------
    >>> maps = LiveMaps()
    >>> maps.last_heartbeat is None
    True
    """

    def __init__(self) -> None:
        self._condition = threading.Condition()
        self._request: _Request | None = None
        self._ended: str | None = None
        self._heartbeat: Heartbeat | None = None
        self.results = 0

    @property
    def last_heartbeat(self) -> Heartbeat | None:
        """The PLC status of the station's latest result (None before any)."""
        with self._condition:
            return self._heartbeat

    @property
    def collecting(self) -> bool:
        """True while a measurement waits for maps."""
        with self._condition:
            return self._request is not None

    def __call__(self, record: CycleRecord) -> None:
        """The station's sink: called on the station's thread for every result."""
        with self._condition:
            self.results += 1
            output = record.result.output
            if output is not None and output.heartbeat is not None:
                self._heartbeat = output.heartbeat
            request = self._request
            if request is None or len(request.window) >= request.count or request.looked >= request.max_results:
                return
            sample = sample_of(record)
            if sample.exposure_time_ns < request.not_before_ns:
                return  # exposed while the machine still polished: not counted at all
            request.looked += 1
            if sample.valid:
                request.window.append(sample)
            else:
                request.window.clear()
                request.last_reason = sample.reason
            self._condition.notify_all()

    def end(self, why: str) -> None:
        """The station stopped (its thread calls this last); a waiting measurement gives up."""
        with self._condition:
            self._ended = why
            self._condition.notify_all()

    def collect(self, count: int, *, max_results: int, not_before_ns: int, timeout_s: float,
                stop: threading.Event, slice_s: float = 0.1) -> list[MapSample]:
        """Wait for ``count`` valid maps in a row exposed at or after ``not_before_ns``.

        Raises
        ------
        UntrustedMeasurement
            Not enough valid maps in a row within ``max_results`` results or ``timeout_s``, the
            station ended, or ``stop`` was set; the message says which, with the last invalid
            result's reason.
        """
        request = _Request(count, max_results, not_before_ns, [])
        deadline = time.monotonic() + timeout_s
        with self._condition:
            self._request = request
            try:
                while len(request.window) < count:
                    if self._ended is not None:
                        raise UntrustedMeasurement(f"the station stopped while measuring: {self._ended}")
                    if stop.is_set():
                        raise UntrustedMeasurement("stopped while measuring")
                    if request.looked >= max_results or time.monotonic() >= deadline:
                        seen = f"{request.looked} result(s) in {timeout_s:g} s" if request.looked < max_results \
                            else f"{request.looked} results (max_results_per_measurement)"
                        last = f"; last invalid: {request.last_reason}" if request.last_reason else ""
                        raise UntrustedMeasurement(f"expected {count} valid results in a row, got "
                                                   f"{len(request.window)} in {seen}{last}")
                    self._condition.wait(slice_s)
                return list(request.window)
            finally:
                self._request = None

    def average(self, count: int, *, not_before_ns: int, timeout_s: float, stop: threading.Event,
                max_results: int | None = None) -> NDArray[np.float64]:
        """The mean of ``count`` valid maps in a row exposed at or after ``not_before_ns``, waves (H, W).

        ``max_results`` defaults to ``4 * count``. A pixel left out of a map (NaN: the quality mask) is
        the mean of the maps that measured it; NaN if none did.

        Raises
        ------
        UntrustedMeasurement
            As :meth:`collect`.
        """
        samples = self.collect(count, max_results=4 * count if max_results is None else max_results,
                               not_before_ns=not_before_ns, timeout_s=timeout_s, stop=stop)
        maps = np.stack([np.asarray(s.waves, dtype=np.float64) for s in samples])
        measured = np.isfinite(maps).sum(axis=0)  # a pixel the quality mask left out of a map: the others'
        total = np.where(np.isfinite(maps), maps, 0.0).sum(axis=0)
        return np.divide(total, measured, out=np.full(total.shape, np.nan), where=measured > 0)
