"""The station's result record: everything one refit produced, as a plain value and as JSON.

The small records on a result (:class:`ApertureRecord`, the fitter's diagnostics, the data
quality's counts, the :class:`OutputRecord` of what went to the PLC) are frozen dataclasses; each
has a ``to_json`` that gives the keys the JSON lines and the recording carry. The records every
instrument's outcome fills (:class:`ApertureRecord`, :class:`FitDiagnostics`,
:class:`~wavestack.pipeline.PixelQuality`) come from :mod:`wavestack.pipeline.instrument`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Union

from wavestack.pipeline.instrument import ApertureRecord, FitDiagnostics, PixelQuality, ReconstructorDiagnostics
from wavestack.station.counters import Counters
from wavestack.station.plc_status import Heartbeat
from wavestack.station.surface_stage import SurfaceRecord

__all__ = ["ApertureRecord", "FitDiagnostics", "FitterDiagnostics", "Heartbeat", "OutputRecord",
           "ReconstructorDiagnostics", "SentCommand", "StationResult", "TruthErrors", "json_ready"]


FitterDiagnostics = Union[FitDiagnostics, ReconstructorDiagnostics]


@dataclass(frozen=True)
class SentCommand:
    """What the safety stage made of one result and whether it went to the PLC.

    Attributes
    ----------
    sent : bool
    command_id : int or None
        The PLC command id, when sent.
    status : str
        The safety flags, e.g. ``"CLIPPED|RATE_LIMITED"`` or ``"HELD|STALE"`` (``"OK"`` for none);
        ``"HELD|TRIPPED"`` and the like when the output's mode sends nothing; ``"...|NOT_SENT"``
        when the PLC did not take the command.
    reason : str or None
    values_nm : tuple of float
        The removal per PLC term after the safety stage, nm (when not sent: what the machine holds
        as far as the host knows).
    """

    sent: bool
    command_id: int | None
    status: str
    reason: str | None
    values_nm: tuple[float, ...]

    def to_json(self) -> dict[str, object]:
        return {"sent": self.sent, "command_id": self.command_id, "status": self.status, "reason": self.reason,
                "values_nm": list(self.values_nm)}


@dataclass(frozen=True)
class OutputRecord:
    """What the output stage did for one result: the heartbeat, the command, and whether the PLC's
    display block took the result (None: the PLC has no display block); JSON key ``plc_display``."""

    heartbeat: Heartbeat | None
    command: SentCommand
    displayed: bool | None = None

    @property
    def sent(self) -> bool:
        return self.command.sent

    def to_json(self) -> dict[str, object]:
        shown = {} if self.displayed is None else {"plc_display": self.displayed}
        return {**(self.heartbeat.to_json() if self.heartbeat is not None else {}), **self.command.to_json(), **shown}


@dataclass(frozen=True)
class TruthErrors:
    """Simulated devices only: RMS of the true wavefront and of measured minus true, waves."""

    truth_rms: float | None
    error_rms: float | None


@dataclass(frozen=True)
class StationResult:
    """One result of the station.

    Attributes
    ----------
    index : int
        Result number in this run, from 0.
    frame_ids : tuple of int
        Device frame ids of the set (one for the carrier method).
    exposure_time_ns : int
        Host time (``time.time_ns``) of the first frame of the set.
    latency_ms : float
        From the first frame's arrival on the host to this result.
    valid : bool
        False: no coefficients to trust; ``reason`` says why. Invalid results are never forwarded
        to the PLC.
    reason : str or None
    coefficients : tuple of float
        Zernike coefficients of the wavefront, ``units`` (waves), ``ordering`` and
        ``normalisation``, starting at index 1 of the ordering (Noll j = 1 is piston).
    ordering, normalisation, units : str
    residual_rms : float
        RMS of the fit residual, waves (NaN when invalid).
    residual_pv : float
        Peak-to-valley of the fit residual, waves, over the same samples as ``residual_rms``
        (the fit grid's pixels used; Shack-Hartmann: the slope misfit times the pitch, as for the
        RMS); NaN when invalid.
    pv : float
        Peak-to-valley of the measured wavefront less the removed physical terms (piston, tilt),
        waves, over the pixels used (Shack-Hartmann: of the modal reconstruction less piston and
        tilt at the lit lenslets' centres); NaN when invalid or not computed.
    pvr : float
        Evans' robust PV: the PV of the 36-term Fringe Zernike fit of the same map plus three
        times that fit's residual RMS, waves; NaN when invalid or not computed, and always for a
        Shack-Hartmann sensor (slopes give no measured map).
    quality : PixelQuality or None
        What the data-quality mask left out inside the aperture (``inside``, ``used``,
        ``excluded``, ``low_modulation``, ``saturated``, ``untrusted_order``, ``clipped``).
    fitter : str
        Method of the fitter that ran (``csf-qcm``, ``qr``, ...).
    fitter_fallback : bool
        True when a ``qr`` fitter stood in while the configured one was being built.
    fitter_diagnostics : FitDiagnostics or ReconstructorDiagnostics or None
        Condition number (``gram_condition``), map fold-overs (``flips``), largest Beltrami
        coefficient (``max_beltrami``); or a reconstructor's condition and lenslet counts.
    aperture : ApertureRecord or None
        ``id`` (counted per run), ``changed`` (this set started it), ``topology``,
        ``components``, ``valid_pixels``.
    unwrap_path : str or None
        "spatial" or "temporal".
    counters : Counters
        Frames and sets so far, each adding up exactly (see :class:`Counters`).
    timings_ms : dict
        Milliseconds per stage.
    truth_rms, truth_error_rms : float or None
        Simulated devices only: RMS of the simulator's true wavefront (piston, tilt removed as the
        fit removes them) and RMS of the measured minus the true wavefront, both over the fitted
        aperture (the pixels the fitter was built on) in the fitted subspace, waves. The measured
        coefficients come from the pixels the quality mask left in: where it leaves out many (a
        saturated band), the physical tilt removal and a mapped basis see another pixel set, and
        this figure grows with that, not with an error of the pixels used.
    output : OutputRecord or None
        What went to the PLC: ``sent`` (bool), ``status`` flags, ``command_id``.
    surface : SurfaceRecord or None
        With ``[surface] enabled``: the ISO form figures, PVr and the drawing's verdict of the
        measured surface (nm), on valid interferometer results.
    calibration : str or None
        The content hash (SHA-256, hex) of the reference calibration subtracted from the map
        (``[processing] calibration``, ``--calibration``); None without one.
    """

    index: int
    frame_ids: tuple[int, ...]
    exposure_time_ns: int
    latency_ms: float
    valid: bool
    reason: str | None
    coefficients: tuple[float, ...]
    ordering: str
    normalisation: str
    units: str
    residual_rms: float
    residual_pv: float
    fitter: str | None
    fitter_fallback: bool
    fitter_diagnostics: FitterDiagnostics | None
    aperture: ApertureRecord | None
    unwrap_path: str | None
    counters: Counters
    timings_ms: dict[str, float] = field(default_factory=dict)
    truth_rms: float | None = None
    truth_error_rms: float | None = None
    output: OutputRecord | None = None
    pv: float = float("nan")
    pvr: float = float("nan")
    quality: PixelQuality | None = None
    surface: SurfaceRecord | None = None
    calibration: str | None = None

    @classmethod
    def invalid(cls, index: int, reason: str, counters: Counters, *, ordering: str,
                exposure_time_ns: int = 0) -> StationResult:
        """A result without a measurement (a lost device, a template row): no frames, no fit."""
        return cls(index=index, frame_ids=(), exposure_time_ns=exposure_time_ns, latency_ms=0.0, valid=False,
                   reason=reason, coefficients=(), ordering=ordering, normalisation="rms", units="waves",
                   residual_rms=float("nan"), residual_pv=float("nan"), fitter=None, fitter_fallback=False,
                   fitter_diagnostics=None, aperture=None, unwrap_path=None, counters=counters)

    @property
    def aperture_changed(self) -> bool:
        """True when this set started a new aperture."""
        return self.aperture is not None and self.aperture.changed

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict with ``"type": "result"`` first; NaN becomes null."""
        values: dict[str, Any] = {f.name: getattr(self, f.name) for f in fields(self)}
        values["frame_ids"] = list(self.frame_ids)
        values["coefficients"] = list(self.coefficients)
        values["counters"] = self.counters.to_json()
        values["timings_ms"] = dict(self.timings_ms)
        values["fitter_diagnostics"] = {} if self.fitter_diagnostics is None else self.fitter_diagnostics.to_json()
        values["aperture"] = {} if self.aperture is None else self.aperture.to_json()
        values["output"] = None if self.output is None else self.output.to_json()
        values["quality"] = {} if self.quality is None else self.quality.to_json()
        values["surface"] = None if self.surface is None else self.surface.to_json()
        return {"type": "result", **json_ready(values)}


def json_ready(value: Any) -> Any:
    """Replace NaN and infinities by None, recursively (JSON has no NaN)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: json_ready(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(item) for item in value]
    return value
