"""Hostile visitors of the live web view, on loopback: DNS rebinding and a flood of browsers.

A page on another site that re-points its own name at 127.0.0.1 sends ``Host: its.name``; the
view must not answer it. Dozens of browsers (or a script opening sockets) may not cost the station
more than the cap allows, and an update is serialised once, not once per browser.
"""

from __future__ import annotations

import asyncio
import json
import urllib.error
import urllib.request

import aiohttp
import numpy as np

from wavestack.web import LiveFeed, WebViewServer

TIMEOUT_S = 10.0  # bounds every wait


def _get(url: str, host: str | None) -> int:
    request = urllib.request.Request(url, headers={"Host": host} if host else {})
    try:
        with urllib.request.urlopen(request, timeout=TIMEOUT_S) as reply:
            return reply.status
    except urllib.error.HTTPError as error:
        return error.code


def _ready(server: WebViewServer) -> None:
    for _ in range(int(TIMEOUT_S / 0.05)):  # the first tick publishes the waiting state
        if _get(server.url + "update.json", None) == 200:
            return
        asyncio.run(asyncio.sleep(0.05))


def test_a_rebound_name_gets_nothing_and_this_machine_gets_everything() -> None:
    with WebViewServer(LiveFeed("wavestack run"), port=0, tick_s=0.05) as server:
        _ready(server)
        port = server.bound_port
        for path in ("", "static/app.js", "update.json"):
            assert _get(server.url + path, f"evil.example:{port}") == 421, path
            assert _get(server.url + path, f"localhost:{port}") == 200, path
            assert _get(server.url + path, f"127.0.0.1:{port}") == 200, path

        async def websocket(host: str) -> int:
            async with aiohttp.ClientSession() as session:
                try:
                    async with session.ws_connect(f"ws://127.0.0.1:{port}/ws", headers={"Host": host}):
                        return 101
                except aiohttp.WSServerHandshakeError as error:
                    return error.status

        assert asyncio.run(websocket(f"evil.example:{port}")) == 421
        assert asyncio.run(websocket(f"127.0.0.1:{port}")) == 101


def test_a_flood_of_browsers_is_capped_and_each_update_is_serialised_once() -> None:
    feed = LiveFeed("wavestack run", min_render_s=0.0, max_side=64)
    with WebViewServer(feed, port=0, tick_s=0.02, max_browsers=8) as server:
        url = server.url.replace("http", "ws") + "ws"

        async def flood() -> tuple[list[int], int]:
            async with aiohttp.ClientSession() as session:
                opened, refused = [], []
                for _ in range(30):
                    try:
                        opened.append(await session.ws_connect(url))
                    except aiohttp.WSServerHandshakeError as error:
                        refused.append(error.status)
                before = server.serialisations
                for _ in range(20):  # every served browser receives each update
                    await asyncio.sleep(0.03)
                    for ws in opened:
                        while True:
                            try:
                                await ws.receive(timeout=0.001)
                            except asyncio.TimeoutError:
                                break
                made = server.serialisations - before
                for ws in opened:
                    await ws.close()
                return refused, made

        refused, made = asyncio.run(flood())
    assert refused == [503] * 22  # 8 served, the rest refused before any work
    # 20 ticks of ~0.03 s: at most ~40 updates, each serialised once per variant (with the history,
    # without): never the 8 x 40 = 320 texts of one serialisation per browser
    assert made <= 2 * 40 + 8


def test_update_json_is_one_text_per_update() -> None:
    feed = LiveFeed("wavestack run")
    with WebViewServer(feed, port=0, tick_s=10.0) as server:
        _ready(server)
        before = server.serialisations
        for _ in range(20):
            assert _get(server.url + "update.json", None) == 200
        assert server.serialisations - before <= 1
        body = urllib.request.urlopen(server.url + "update.json", timeout=TIMEOUT_S).read()
        assert json.loads(body)["browser"]["clients"] == 0 and np.isfinite(len(body))
