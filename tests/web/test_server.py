"""The web view's server: the page's files, the JSON, and the WebSocket per browser with its newest-wins slot."""

from __future__ import annotations

import asyncio
import base64
import json
import os
import socket
import urllib.error
import urllib.request

import aiohttp
import numpy as np
import pytest

from wavestack.station import Counters, CycleRecord, StationResult
from wavestack.web import LatestSlot, LiveFeed, WebViewServer


def _get(url: str) -> tuple[int, dict[str, str], bytes]:
    try:
        with urllib.request.urlopen(url, timeout=10) as response:
            return response.status, dict(response.headers), response.read()
    except urllib.error.HTTPError as error:
        with error:
            return error.code, dict(error.headers), error.read()


def test_the_slot_keeps_only_the_newest_and_counts_what_it_replaced() -> None:
    async def run() -> tuple[list[int], int, int]:
        slot: LatestSlot[int] = LatestSlot()
        slot.put(1)
        first = await slot.get()
        for value in (2, 3, 4):
            slot.put(value)
        waiter = asyncio.ensure_future(slot.get())
        await asyncio.sleep(0)
        return [first, await waiter], slot.dropped, slot.taken

    assert asyncio.run(run()) == ([1, 4], 2, 2)


def test_the_page_and_its_files_are_served_from_the_package_only() -> None:
    with WebViewServer(LiveFeed("wavestack run"), port=0) as server:
        status, headers, body = _get(server.url)
        assert status == 200 and b'<script src="/static/app.js"' in body and "default-src 'self'" in \
            headers["Content-Security-Policy"]
        for name, kind in (("app.js", "text/javascript"), ("style.css", "text/css")):
            status, headers, body = _get(server.url + "static/" + name)
            assert status == 200 and headers["Content-Type"].startswith(kind) and len(body) > 500
        assert _get(server.url + "static/..%2Fserver.py")[0] == 404
        assert _get(server.url + "static/feed.py")[0] == 404
        status, _, body = _get(server.url + "update.json")
        assert status == 200 and json.loads(body)["state"] == "waiting"
        for path in ("", "static/app.js", "static/style.css"):  # nothing fetched from elsewhere
            text = _get(server.url + path)[2].replace(b"http://www.w3.org/2000/svg", b"")  # SVG's namespace name
            assert b"http://" not in text and b"https://" not in text and b"//" + b"cdn" not in text, path


def test_a_busy_port_is_an_os_error_and_leaves_nothing_running() -> None:
    with WebViewServer(LiveFeed("a"), port=0) as first:
        with pytest.raises(OSError):
            WebViewServer(LiveFeed("b"), port=first.bound_port).start()


def _noise_record(index: int, side: int = 256) -> CycleRecord:
    result = StationResult.invalid(index, "", Counters.zero(5), ordering="noll")
    rng = np.random.default_rng(index)
    return CycleRecord(result, waves=rng.standard_normal((side, side)))  # incompressible: large PNGs


def _stalled_browser(port: int) -> socket.socket:
    """A WebSocket client that shakes hands and then never reads, with a small receive window."""
    raw = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    raw.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    raw.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    raw.sendall((f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                 f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n").encode())
    return raw


def test_a_browser_that_does_not_read_drops_its_own_updates_and_slows_no_one() -> None:
    feed = LiveFeed("wavestack run", min_render_s=0.0, max_side=256)
    with WebViewServer(feed, port=0, tick_s=0.01) as server:
        stalled = _stalled_browser(server.bound_port)
        try:
            async def read_along() -> list[dict]:
                seen: list[dict] = []
                async with aiohttp.ClientSession() as session:
                    async with session.ws_connect(server.url.replace("http", "ws") + "ws") as ws:
                        for index in range(60):
                            feed(_noise_record(index))
                            while True:  # until this result's page arrives
                                message = json.loads((await ws.receive(timeout=30)).data)
                                seen.append(message)
                                if message["station"] and message["station"]["last_index"] == index:
                                    break
                return seen

            seen = asyncio.run(read_along())
        finally:
            stalled.close()
    seqs = [m["seq"] for m in seen]
    assert seqs == sorted(set(seqs))  # in order, none twice
    assert seen[-1]["station"]["last_index"] == 59  # the reader kept up to the newest result
    # ~60 maps of ~350 kB each: far more than the stalled browser's buffers hold
    assert seen[-1]["browser"]["clients"] == 2 and seen[-1]["browser"]["dropped_all"] > seen[-1]["browser"]["dropped"]


def test_a_websocket_from_another_site_is_refused() -> None:
    with WebViewServer(LiveFeed("wavestack run"), port=0) as server:
        async def connect() -> int:
            async with aiohttp.ClientSession() as session:
                try:
                    async with session.ws_connect(server.url.replace("http", "ws") + "ws",
                                                  headers={"Origin": "http://example.invalid"}):
                        return 101
                except aiohttp.WSServerHandshakeError as error:
                    return error.status

        assert asyncio.run(connect()) == 403


def test_stop_sends_the_stopped_state_then_closes_the_socket() -> None:
    feed = LiveFeed("wavestack run")
    server = WebViewServer(feed, port=0, tick_s=0.05)
    server.start()

    async def watch() -> list[dict]:
        messages = []
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(server.url.replace("http", "ws") + "ws") as ws:
                messages.append(json.loads((await ws.receive(timeout=30)).data))
                feed.end("stopped after 0 results")
                await asyncio.get_running_loop().run_in_executor(None, server.stop)
                async for message in ws:
                    messages.append(json.loads(message.data))
        return messages

    try:
        messages = asyncio.run(watch())
    finally:
        server.stop()
    assert messages[0]["state"] == "waiting" and messages[-1]["state"] == "stopped"
    assert messages[-1]["detail"] == "stopped after 0 results"
