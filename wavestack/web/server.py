"""The web view's server: aiohttp on its own thread and event loop, the page, and a WebSocket per browser.

:class:`WebViewServer` serves the page (``/``, ``/static/...``: HTML, CSS and JavaScript shipped
in this package, nothing fetched from elsewhere), the newest update as JSON (``/update.json``)
and pushes updates over a WebSocket (``/ws``). A tick every ``tick_s`` asks the feed for an
update (:meth:`~wavestack.web.feed.LiveFeed.update`, which renders the map on this thread, never
on the station's) and offers it to every browser's :class:`~wavestack.web.slots.LatestSlot`. The
page is read-only: a browser sends nothing the server acts on.

:meth:`WebViewServer.stop` sends the last update (the stopped state) to every browser that keeps
up, closes their sockets, the listening socket and the loop, and joins the thread.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from dataclasses import dataclass, field
from importlib import resources
from urllib.parse import urlsplit

from aiohttp import WSCloseCode, web

from wavestack.web.feed import LiveFeed
from wavestack.web.hosts import host_name, machine_names, names_allowed
from wavestack.web.slots import LatestSlot
from wavestack.web.view import BrowserCounts, LiveUpdate, update_body, with_counts

logger = logging.getLogger(__name__)

__all__ = ["WebViewServer"]

_STATIC = {"index.html": "text/html", "app.js": "text/javascript", "style.css": "text/css"}
_HEADERS = {"Content-Security-Policy": "default-src 'self'; img-src 'self' data:; connect-src 'self'",
            "Cache-Control": "no-store", "X-Content-Type-Options": "nosniff"}
_FLUSH_S = 1.0  # the last update's time to reach the browsers at stop


def _static_files() -> dict[str, bytes]:
    folder = resources.files("wavestack.web") / "static"
    return {name: (folder / name).read_bytes() for name in _STATIC}


@dataclass(eq=False)
class _Browser:
    slot: LatestSlot[LiveUpdate] = field(default_factory=LatestSlot)
    map_seq: int = -1
    history_seq: int = -1
    sent: int = 0


class WebViewServer:
    """The page and its WebSockets on ``host:port`` (module notes).

    Parameters
    ----------
    feed : LiveFeed
    host : str
        Address to listen on (the caller checks that it is allowed).
    port : int
        0 for any free port.
    tick_s : float
        Period of the updates, s.
    max_browsers : int
        WebSockets served at once.

    Example
    -------
    >>> with WebViewServer(LiveFeed("demo"), port=0) as server:
    ...     server.url.startswith("http://127.0.0.1:")
    True
    """

    def __init__(self, feed: LiveFeed, *, host: str = "127.0.0.1", port: int = 0, tick_s: float = 0.2,
                 max_browsers: int = 16) -> None:
        self._feed, self._host, self._port, self._tick_s = feed, host, port, tick_s
        self.max_browsers = max_browsers
        self._machine = machine_names()
        self._bodies: dict[tuple[int, bool, bool], str] = {}  # the latest update's texts, by variant
        self.serialisations = 0  #: update texts made (one per update and variant, not per browser)
        self.refused = 0  #: requests refused: a Host that is not this machine, one browser too many
        self._files = _static_files()
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._browsers: set[_Browser] = set()
        self._sockets: set[web.WebSocketResponse] = set()
        self._latest: LiveUpdate | None = None
        self._dropped_gone = 0  # of browsers that left
        self.bound_port = 0

    @property
    def url(self) -> str:
        """``http://HOST:PORT/`` (IPv6 literals bracketed)."""
        host = f"[{self._host}]" if ":" in self._host else self._host
        return f"http://{host}:{self.bound_port}/"

    def __enter__(self) -> WebViewServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ life
    def start(self, timeout_s: float = 10.0) -> None:
        """Listen, serve on the server's thread; returns once it accepts connections.

        Raises
        ------
        OSError
            The address cannot be bound (in use, not an address of this machine).
        """
        self._thread = threading.Thread(target=self._serve, name="wavestack-web", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout_s):
            raise TimeoutError(f"the web view did not start within {timeout_s:g} s")
        if self._error is not None:
            self._thread.join()
            self._thread = None
            raise self._error

    def stop(self) -> None:
        """Send the last update, close every socket, end the thread; idempotent."""
        thread, self._thread = self._thread, None
        if thread is None:
            return
        if self._loop is not None and self._stopping is not None:
            try:
                self._loop.call_soon_threadsafe(self._stopping.set)
            except RuntimeError:  # the loop already ended (an error, logged)
                pass
        thread.join()

    def _serve(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as error:  # reported to start(); after start, logged
            if not self._ready.is_set():
                self._error = error
            else:
                logger.error("the web view stopped: %s", error, exc_info=True)
        finally:
            self._ready.set()

    async def _main(self) -> None:
        self._loop, self._stopping = asyncio.get_running_loop(), asyncio.Event()
        app = web.Application(middlewares=[self._only_this_machine])
        app.add_routes([web.get("/", self._index), web.get("/static/{name}", self._static),
                        web.get("/update.json", self._update_json), web.get("/ws", self._websocket)])
        runner = web.AppRunner(app, handle_signals=False, access_log=None, shutdown_timeout=_FLUSH_S)
        await runner.setup()
        try:
            site = web.TCPSite(runner, self._host, self._port)
            await site.start()
            self.bound_port = runner.addresses[0][1]
            self._ready.set()
            logger.info("web view on %s", self.url)
            await self._tick_until_stopped()
            await self._close_browsers()
        finally:
            await runner.cleanup()

    async def _tick_until_stopped(self) -> None:
        assert self._stopping is not None
        while not self._stopping.is_set():
            self._publish()
            try:
                await asyncio.wait_for(self._stopping.wait(), self._tick_s)
            except TimeoutError:
                pass
        self._publish()  # the stopped state

    def _publish(self) -> None:
        try:
            update = self._feed.update()
        except Exception as error:  # a bug in one update must not end the view (or the station)
            logger.error("web view update failed: %s", error, exc_info=True)
            return
        if update is None:
            return
        self._latest = update
        self._bodies = {}
        for browser in self._browsers:
            browser.slot.put(update)

    async def _close_browsers(self) -> None:
        """Give the last update up to ``_FLUSH_S`` to go out, then close every WebSocket."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + _FLUSH_S
        while any(b.slot.waiting or b.sent < b.slot.taken for b in self._browsers) and loop.time() < deadline:
            await asyncio.sleep(0.02)
        for ws in list(self._sockets):
            if ws.prepared:  # a handshake still under way is ended with the server
                await ws.close(code=WSCloseCode.GOING_AWAY, message=b"the station stopped")

    # ------------------------------------------------------------------ handlers
    @web.middleware
    async def _only_this_machine(self, request: web.Request, handler):  # type: ignore[no-untyped-def]
        sockname = request.transport.get_extra_info("sockname") if request.transport is not None else None
        arrived_on = str(sockname[0]).lower() if sockname else None
        if not names_allowed(host_name(request.headers.get("Host")), bound=self._host, arrived_on=arrived_on,
                             machine=self._machine):
            self.refused += 1
            raise web.HTTPMisdirectedRequest(text="the web view answers requests for this machine only")
        return await handler(request)

    def _body(self, update: LiveUpdate, with_png: bool, with_history: bool) -> str:
        """The update's text for one variant, made once (:func:`~wavestack.web.view.update_body`)."""
        key = (update.seq, with_png, with_history)
        text = self._bodies.get(key)
        if text is None:
            text = self._bodies[key] = update_body(update, with_png=with_png, with_history=with_history)
            self.serialisations += 1
        return text

    async def _index(self, request: web.Request) -> web.Response:
        return self._file("index.html")

    async def _static(self, request: web.Request) -> web.Response:
        name = request.match_info["name"]
        if name not in _STATIC or name == "index.html":
            raise web.HTTPNotFound(text=f"no such file: {name}")
        return self._file(name)

    def _file(self, name: str) -> web.Response:
        return web.Response(body=self._files[name], content_type=_STATIC[name], headers=_HEADERS)

    async def _update_json(self, request: web.Request) -> web.Response:
        if self._latest is None:
            raise web.HTTPServiceUnavailable(text="no update yet")
        text = with_counts(self._body(self._latest, True, True), self._counts(None))
        return web.Response(text=text, content_type="application/json", headers=_HEADERS)

    def _counts(self, browser: _Browser | None) -> BrowserCounts:
        dropped_all = self._dropped_gone + sum(b.slot.dropped for b in self._browsers)
        return BrowserCounts(browser.sent if browser else 0, browser.slot.dropped if browser else 0,
                             len(self._browsers), dropped_all)

    async def _websocket(self, request: web.Request) -> web.WebSocketResponse:
        origin = request.headers.get("Origin")
        if origin is not None and urlsplit(origin).netloc != request.host:  # another site's page
            raise web.HTTPForbidden(text="the web view serves its own page only")
        if len(self._sockets) >= self.max_browsers:
            self.refused += 1
            raise web.HTTPServiceUnavailable(text=f"the web view serves {self.max_browsers} browsers at once")
        ws = web.WebSocketResponse(heartbeat=10.0, timeout=_FLUSH_S)  # timeout: for the close handshake
        self._sockets.add(ws)  # counted from here: handshakes under way count against the cap too
        browser, sender = _Browser(), None
        try:
            await ws.prepare(request)
            self._browsers.add(browser)
            if self._latest is not None:
                browser.slot.put(self._latest)
            sender = asyncio.create_task(self._send(ws, browser))
            async for _ in ws:  # the page sends nothing; this ends when the browser goes
                pass
        finally:
            if sender is not None:
                sender.cancel()
                await asyncio.gather(sender, return_exceptions=True)
            self._browsers.discard(browser)
            self._sockets.discard(ws)
            self._dropped_gone += browser.slot.dropped
        return ws

    async def _send(self, ws: web.WebSocketResponse, browser: _Browser) -> None:
        while not ws.closed:
            update = await browser.slot.get()
            with_png = update.map is not None and update.map.seq != browser.map_seq
            with_history = update.history is not None and update.history.seq != browser.history_seq
            text = with_counts(self._body(update, with_png, with_history), self._counts(browser))
            try:
                await ws.send_str(text)
            except (ConnectionError, RuntimeError):  # the browser went while we wrote
                return
            browser.sent += 1
            browser.map_seq = update.map.seq if update.map is not None else browser.map_seq
            browser.history_seq = update.history.seq if update.history is not None else browser.history_seq
