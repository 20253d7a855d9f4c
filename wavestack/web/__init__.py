"""The live web view: the station's map, numbers and a loop's history in a browser, pushed as they come.

:class:`LiveFeed` is a result sink (and takes the polishing and alignment loops' callbacks);
:class:`WebViewServer` serves the page (plain HTML, CSS and JavaScript shipped in this package)
and pushes a :class:`LiveUpdate` over a WebSocket to each browser, a slow one dropping updates
for itself only (:class:`LatestSlot`). Maps are rendered on the server's thread by
:func:`render_map`: a downsampled false-colour PNG with its colour scale and aperture outline.
"""

from __future__ import annotations

from wavestack.web.feed import LiveFeed, station_panel
from wavestack.web.render import COLOURS, LEFT_OUT_COLOUR, downsample, render_map
from wavestack.web.server import WebViewServer
from wavestack.web.slots import LatestSlot
from wavestack.web.view import (
    BrowserCounts,
    Coefficient,
    HistoryPanel,
    LiveUpdate,
    MapImage,
    StationPanel,
    update_message,
)

__all__ = ["BrowserCounts", "COLOURS", "Coefficient", "LEFT_OUT_COLOUR", "HistoryPanel", "LatestSlot", "LiveFeed", "LiveUpdate",
           "MapImage", "StationPanel", "WebViewServer", "downsample", "render_map", "station_panel",
           "update_message"]
