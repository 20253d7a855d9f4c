"""The live view's statistics: rate, latency percentiles, trends, last invalid reason."""

from __future__ import annotations

from wavestack.station import (
    ApertureRecord,
    Counters,
    FrameCounts,
    LiveStats,
    SetCounts,
    StationResult,
    render_live_view,
)


def _counters(index: int) -> Counters:
    """Five-frame sets: index + 1 processed, index dropped, and 2 more frames dropped by the camera."""
    sets = SetCounts(assembled=2 * index + 1, processed=index + 1, dropped=index, pending=0)
    return Counters(5, FrameCounts(acquired=10 * index + 7, processed=5 * (index + 1), dropped=5 * index + 2,
                                   pending=0), sets)


def _result(index: int, latency_ms: float, z4: float, valid: bool = True) -> StationResult:
    return StationResult(
        index=index, frame_ids=(index,), exposure_time_ns=0, latency_ms=latency_ms, valid=valid,
        reason=None if valid else "aperture: empty", coefficients=(0.0, 0.0, 0.0, z4, 0.1) if valid else (),
        ordering="noll", normalisation="rms", units="waves", residual_rms=0.01, residual_pv=0.08 + index * 1e-3,
        fitter="csf-qcm",
        fitter_fallback=False, fitter_diagnostics=None,
        aperture=ApertureRecord(id=0, changed=False, topology="simply connected", valid_pixels=100),
        unwrap_path="temporal", counters=_counters(index), truth_error_rms=0.002)


def test_rate_latency_trend_and_reason() -> None:
    stats = LiveStats(window=10)
    for k in range(10):  # one result every 50 ms, latencies 10..100 ms, Z4 rising by 0.01 a result
        stats.add(_result(k, 10.0 * (k + 1), 0.3 + 0.01 * k, valid=k != 4), now_ns=k * 50_000_000)
    snap = stats.snapshot()
    assert abs(snap.results_per_s - 20.0) < 1e-9
    assert snap.latency_p50_ms == 55.0  # median of 10, 20, ..., 100
    assert snap.results == 10 and snap.valid == 9 and snap.counters == _counters(9)
    (j, value, change), = [t for t in snap.leading if t[0] == 4]
    assert j == 4 and abs(value - 0.39) < 1e-12 and abs(change - 0.09) < 1e-12
    lines = render_live_view(snap, "noll")
    assert lines[1] == "frames acquired 97 = 50 in processed sets + 47 dropped + 0 pending"
    assert lines[2] == "sets of 5 assembled 19 = 10 processed + 9 dropped + 0 pending"
    assert "Z4=+0.3900+" in lines[4] and "Z5=+0.1000=" in lines[4]
    assert lines[5] == "fit residual: rms 0.0100  pv 0.0890 waves"  # the last valid result's (index 9)
    assert lines[-1] == "last invalid: aperture: empty"
