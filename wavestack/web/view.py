"""What the web view shows, as frozen values: one :class:`LiveUpdate` is the whole page at one moment.

The feed (:mod:`wavestack.web.feed`) builds an update from the station's records and the loops'
callbacks; the server sends it to every browser as one JSON text message
(:func:`update_message`). The map's PNG and the history go out only when they changed since that
browser's last message (the message says which ``seq`` it carries), so a browser that keeps up
receives each picture once.
"""

from __future__ import annotations

import base64
import json
import math
from dataclasses import dataclass
from typing import Any

from wavestack.loop import Cell

__all__ = ["BrowserCounts", "Coefficient", "HistoryPanel", "LiveUpdate", "MapImage", "StationPanel",
           "update_body", "update_message", "with_counts"]

Polygon = tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class MapImage:
    """A map rendered for the browser: a false-colour PNG with its colour scale.

    Attributes
    ----------
    seq : int
        Counts renders from 1; a browser is sent the PNG once per ``seq``.
    png : bytes
        RGBA PNG, ``width`` x ``height`` pixels; transparent outside the aperture.
    width, height : int
        Pixels of the PNG (the map downsampled by ``factor``).
    factor : int
        Map pixels per PNG pixel, each way.
    vmin, vmax : float
        The colour scale's ends, ``units``.
    colours : tuple of str
        The colour scale from ``vmin`` to ``vmax``, evenly spaced ``#rrggbb`` stops (the page's colour bar).
    units : str
    rms, pv : float
        RMS and peak-to-valley of the full-resolution map, ``units``.
    outline : tuple of polygons
        The aperture's outline (outer edges and holes) in PNG pixel coordinates (x right, y down,
        pixel centres at half-integers), for an SVG drawn over the image.
    left_out : int
        Pixels inside the aperture the data-quality mask left out of the map; the PNG paints every
        block holding one in :data:`~wavestack.web.render.LEFT_OUT_COLOUR`.
    title : str
        What the map is ("wavefront of result 12", "field point 2").
    render_ms : float
        What rendering it cost (downsampling, colouring, PNG), ms.
    """

    seq: int
    png: bytes
    width: int
    height: int
    factor: int
    vmin: float
    vmax: float
    colours: tuple[str, ...]
    units: str
    rms: float
    pv: float
    outline: tuple[Polygon, ...]
    title: str
    render_ms: float
    left_out: int = 0


@dataclass(frozen=True)
class Coefficient:
    """One leading coefficient: its index in the ordering, name, newest value and change over the window."""

    index: int
    name: str
    value: float
    change: float


@dataclass(frozen=True)
class StationPanel:
    """The station's numbers (the terminal's live view, and more).

    Attributes
    ----------
    results, valid : int
    last_index : int
        Index of the newest result (``-1`` before any).
    shown_index : int
        Index of the result whose coefficients and residual are shown (the newest valid one; -1 if none).
    results_per_s, latency_p50_ms, latency_p99_ms : float
        Over the last window of results (:class:`~wavestack.station.LiveStats`).
    frames, sets : tuple of int
        ``(acquired or assembled, processed, dropped, pending)``.
    frames_per_set : int
    aperture, fitter : str
    kappa : float or None
        Condition number of the fitter's Gram matrix (a reconstructor's condition number).
    flips : int or None
        Fold-overs of the CSF-QCM map.
    max_mu : float or None
        Largest Beltrami coefficient ``|mu|`` of the map.
    ordering : str
    coefficients : tuple of Coefficient
        Waves of wavefront.
    residual_rms, residual_pv : float or None
        Of the shown result's fit residual, waves.
    pv, pvr : float or None
        The shown result's wavefront PV and Evans' robust PV, waves.
    quality : tuple of int or None
        The shown result's pixels ``(inside, used, low modulation, saturated, fringe order, clipped, rim)``.
    surface : tuple or None
        With ``[surface]`` on: the shown result's ``(IRR nm, RMSt nm, PVr nm)`` of surface, and with a
        drawing tolerance ``(notation, passed, limiting quantity)`` in :attr:`spec`.
    spec : tuple of (str, bool, str) or None
    truth_error_rms : float or None
        Simulated devices: measured minus true, waves RMS.
    safety : str or None
        The safety stage's flags for the newest result (``"OK"``, ``"CLIPPED|RATE_LIMITED"``, ``"HELD|STALE"``).
    sent : bool or None
        The newest command went to the PLC.
    plc_state : str or None
        The output's mode (``ARMED``, ``TRIPPED``, ...).
    heartbeat_ok : bool or None
    last_reason : str or None
        Why the last invalid result was invalid.
    """

    results: int
    valid: int
    last_index: int
    shown_index: int
    results_per_s: float
    latency_p50_ms: float
    latency_p99_ms: float
    frames: tuple[int, int, int, int]
    sets: tuple[int, int, int, int]
    frames_per_set: int
    aperture: str
    fitter: str
    kappa: float | None
    flips: int | None
    max_mu: float | None
    ordering: str
    coefficients: tuple[Coefficient, ...]
    residual_rms: float | None
    residual_pv: float | None
    truth_error_rms: float | None
    safety: str | None
    sent: bool | None
    plc_state: str | None
    heartbeat_ok: bool | None
    last_reason: str | None
    pv: float | None = None
    pvr: float | None = None
    quality: tuple[int, int, int, int, int, int, int] | None = None
    surface: tuple[float, float, float] | None = None
    spec: tuple[str, bool, str] | None = None


@dataclass(frozen=True)
class HistoryPanel:
    """A loop's history: ``polish`` runs or ``align`` iterations, and where the loop is.

    Attributes
    ----------
    kind : str
        ``"polish"`` or ``"align"``.
    seq : int
        Counts changes; a browser is sent the table once per ``seq``.
    columns : tuple of str
        Column headings, with units.
    rows : tuple of tuple
        One row per run or iteration, numbers unformatted.
    trend_label : str
        What :attr:`trend` is ("surface RMS, nm").
    trend : tuple of float
        One figure per measurement, for a small chart.
    phase, reason : str
        The loop's current phase and why it is there.
    """

    kind: str
    seq: int
    columns: tuple[str, ...]
    rows: tuple[tuple[Cell, ...], ...]
    trend_label: str
    trend: tuple[float, ...]
    phase: str
    reason: str


@dataclass(frozen=True)
class LiveUpdate:
    """The whole page at one moment.

    Attributes
    ----------
    seq : int
        Counts updates from 1.
    title : str
        The command (``"wavestack run"``).
    state : str
        ``"waiting"`` (no result yet), ``"running"``, ``"device lost"`` (the newest result says a
        device was lost; the station reconnects) or ``"stopped"``.
    detail : str
        Why, in a line.
    station : StationPanel or None
    map : MapImage or None
    history : HistoryPanel or None
    renders : int
        Maps rendered so far.
    render_ms_mean : float
        Mean cost of a render, ms (NaN before any).
    """

    seq: int
    title: str
    state: str
    detail: str
    station: StationPanel | None
    map: MapImage | None
    history: HistoryPanel | None
    renders: int = 0
    render_ms_mean: float = math.nan


@dataclass(frozen=True)
class BrowserCounts:
    """What one browser's connection and the server have sent and dropped (the page shows them)."""

    sent: int
    dropped: int
    clients: int
    dropped_all: int


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, (list, tuple)):
        return [_finite(item) for item in value]
    return value


def _map_json(image: MapImage, with_png: bool) -> dict[str, object]:
    record: dict[str, object] = {
        "seq": image.seq, "width": image.width, "height": image.height, "factor": image.factor,
        "vmin": _finite(image.vmin), "vmax": _finite(image.vmax), "units": image.units, "rms": _finite(image.rms),
        "pv": _finite(image.pv), "title": image.title, "render_ms": image.render_ms,
        "outline": [[[round(x, 2), round(y, 2)] for x, y in polygon] for polygon in image.outline]}
    if with_png:
        record["colours"] = list(image.colours)
        record["png"] = "data:image/png;base64," + base64.b64encode(image.png).decode("ascii")
    return record


def _station_json(panel: StationPanel) -> dict[str, object]:
    record = {name: _finite(getattr(panel, name)) for name in panel.__dataclass_fields__ if name != "coefficients"}
    record["coefficients"] = [{"index": c.index, "name": c.name, "value": _finite(c.value), "change": _finite(c.change)}
                              for c in panel.coefficients]
    return record


def _history_json(panel: HistoryPanel) -> dict[str, object]:
    return {"kind": panel.kind, "seq": panel.seq, "columns": list(panel.columns),
            "rows": [_finite(list(row)) for row in panel.rows], "trend_label": panel.trend_label,
            "trend": _finite(list(panel.trend)), "phase": panel.phase, "reason": panel.reason}


def update_message(update: LiveUpdate, counts: BrowserCounts, *, with_png: bool, with_history: bool) -> str:
    """One WebSocket text message: the update as JSON (NaN as null), with one browser's figures.

    The update's part is :func:`update_body` (the server serialises it once per update and
    variant, for every browser), the figures are spliced in by :func:`with_counts`.

    Parameters
    ----------
    update : LiveUpdate
    counts : BrowserCounts
        This browser's figures.
    with_png : bool
        Carry the map's PNG (the browser has not had this ``map.seq`` yet); the map's scale and
        outline always go.
    with_history : bool
        Carry the history table (the browser has not had this ``history.seq``).

    Returns
    -------
    str

    Example
    -------
    >>> text = update_message(LiveUpdate(1, "wavestack run", "waiting", "", None, None, None),
    ...                       BrowserCounts(0, 0, 1, 0), with_png=False, with_history=False)
    >>> json.loads(text)["state"], json.loads(text)["browser"]["clients"]
    ('waiting', 1)
    """
    return with_counts(update_body(update, with_png=with_png, with_history=with_history), counts)


def update_body(update: LiveUpdate, *, with_png: bool, with_history: bool) -> str:
    """The update's JSON object without a browser's figures (see :func:`update_message`)."""
    message: dict[str, object] = {
        "type": "update", "seq": update.seq, "title": update.title, "state": update.state, "detail": update.detail,
        "renders": update.renders, "render_ms_mean": _finite(update.render_ms_mean),
        "station": None if update.station is None else _station_json(update.station),
        "map": None if update.map is None else _map_json(update.map, with_png),
        "history": None if update.history is None else (
            _history_json(update.history) if with_history else {"seq": update.history.seq})}
    return json.dumps(message, allow_nan=False, separators=(",", ":"))


def with_counts(body: str, counts: BrowserCounts) -> str:
    """``body`` (a JSON object from :func:`update_body`) with one browser's figures as its ``browser`` member."""
    figures = {"sent": counts.sent, "dropped": counts.dropped, "clients": counts.clients,
               "dropped_all": counts.dropped_all}
    return '{"browser":' + json.dumps(figures, separators=(",", ":")) + "," + body[1:]
