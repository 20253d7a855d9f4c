"""The web view in a real browser: ``wavestack run --web`` on the simulated station, read by headless Chromium.

The station is the default simulated one with a faster defocus drift (0.05 waves/s instead of
0.002), so the map visibly changes within seconds. The page's numbers are checked against the
``--json`` lines of the same results; the map image is decoded back into values through its
colour scale and must change between two results as the drift says. The screenshot is saved to
``build/test-artifacts/web-view.png``.

Chromium is Debian's ``/usr/bin/chromium`` (``python3 ws.py test`` installs it when missing),
driven by Playwright; the test fails, never skips, when it is missing.
"""

from __future__ import annotations

import base64
import json
import math
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np
import pytest

from wavestack.config import DEFAULT_CONFIG
from wavestack.web import COLOURS, LEFT_OUT_COLOUR

ROOT = Path(__file__).resolve().parents[2]
ARTEFACT = ROOT / "build" / "test-artifacts" / "web-view.png"
CHROMIUM = "/usr/bin/chromium"
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]
DRIFT_WAVES_PER_S = 0.05  # Noll 4 (defocus)
WAIT_S = 180.0  # the first result needs the devices and a fitter: generous on a loaded machine


@contextmanager
def chromium_page(profile: Path) -> Iterator:
    """A page in headless Chromium (Debian's, driven by Playwright) on a fresh profile; closed after."""
    from playwright.sync_api import sync_playwright

    assert shutil.which(CHROMIUM), f"{CHROMIUM} is missing: `python3 ws.py test` installs Debian's chromium"
    with sync_playwright() as playwright:
        context = playwright.chromium.launch_persistent_context(
            str(profile), executable_path=CHROMIUM, headless=True, args=FLAGS, viewport={"width": 1280, "height": 1000})
        try:
            yield context.pages[0] if context.pages else context.new_page()
        finally:
            context.close()


def _drifting_station(folder: Path) -> Path:
    text = DEFAULT_CONFIG.read_text()
    drift = re.search(r"^drift_waves_per_s = \[([^\]]*)\]", text, re.M)
    assert drift is not None, "the default station's [optic] drift_waves_per_s line moved"
    values = [float(v) for v in drift.group(1).split(",")]
    values[3] = DRIFT_WAVES_PER_S
    path = folder / "drifting.toml"
    path.write_text(text.replace(drift.group(0), f"drift_waves_per_s = {values}"))
    return path


def _wait_for(what: str, condition, timeout_s: float = WAIT_S, every_s: float = 0.1):  # -> the condition's value
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(every_s)
    raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}")


def _results(stdout: Path) -> dict[int, dict]:
    lines = [json.loads(line) for line in stdout.read_text().splitlines(keepends=True) if line.endswith("\n")]
    return {line["index"]: line for line in lines if line["type"] == "result"}


_READ_PAGE = """() => {
  const img = document.getElementById('map-image');
  const text = id => document.getElementById(id).textContent;
  return {state: text('state'), src: img.getAttribute('src'), seq: img.dataset.seq, title: img.dataset.title || '',
          vmin: Number(img.dataset.vmin), vmax: Number(img.dataset.vmax), shown: text('shown-index'),
          last: text('last-index'), results: text('results'), residual: text('residual-rms'), frames: text('frames'),
          safety: text('safety'), plc: text('plc-state'), fitter: text('fitter'), dropped: text('browser-dropped'),
          coefficients: [...document.querySelectorAll('.bar-row')].map(r => [Number(r.dataset.index), r.dataset.value,
                          document.getElementById('coef-' + r.dataset.index).textContent])};
}"""


def _map_values(page_state: dict) -> np.ndarray:
    """The map the page shows, back in waves: each pixel's colour looked up on the colour scale (NaN outside, and
    where the page paints a pixel the quality mask left out: that colour is no value)."""
    png = base64.b64decode(page_state["src"].split(",", 1)[1])
    bgra = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
    lut = np.array([[int(c[k:k + 2], 16) for k in (5, 3, 1)] for c in COLOURS], dtype=np.float64)  # BGR
    pixels = bgra[..., :3].reshape(-1, 1, 3).astype(np.float64)
    level = np.argmin(((pixels - lut[None]) ** 2).sum(axis=2), axis=1).reshape(bgra.shape[:2])
    values = page_state["vmin"] + level / 255.0 * (page_state["vmax"] - page_state["vmin"])
    left_out = np.all(bgra[..., :3] == [int(LEFT_OUT_COLOUR[k:k + 2], 16) for k in (5, 3, 1)], axis=2)
    return np.where((bgra[..., 3] > 0) & ~left_out, values, np.nan)


def _result_of_map(page_state: dict) -> int:
    match = re.search(r"result (\d+)", page_state["title"])
    assert match, page_state["title"]
    return int(match.group(1))


def _check_numbers(page_state: dict, results: dict[int, dict]) -> None:
    """What the page shows for its newest and its shown result equals their JSON lines."""
    shown, last = results[int(page_state["shown"])], results[int(page_state["last"])]
    assert page_state["coefficients"], "no coefficient bars"
    for index, value, text in page_state["coefficients"]:  # Noll: index j is coefficients[j - 1]
        expected = shown["coefficients"][index - 1]
        assert math.isclose(float(value), expected, rel_tol=1e-12, abs_tol=1e-15), (index, value, expected)
        assert text == f"{expected:+.4f}", (index, text, expected)
    assert page_state["residual"] == f"{shown['residual_rms']:.4f}"
    frames = last["counters"]["frames"]
    assert page_state["frames"] == (f"acquired {frames['acquired']} = {frames['processed']} processed + "
                                    f"{frames['dropped']} dropped + {frames['pending']} pending")
    assert page_state["safety"] == last["output"]["status"] and page_state["plc"] == last["output"]["plc_state"]
    assert page_state["fitter"].startswith(last["fitter"])
    assert int(page_state["results"]) >= int(page_state["last"]) + 1


def _drift_fit(change: np.ndarray) -> tuple[float, float]:
    """Least squares of a map's change on a paraboloid (1, x, y, x^2 + y^2): (r^2 coefficient, variance explained),
    over every shown pixel that holds a value in both maps (the whole shown radius)."""
    y, x = np.nonzero(np.isfinite(change))
    d = change[y, x]
    basis = np.column_stack([np.ones_like(d), x, y, (x - x.mean()) ** 2 + (y - y.mean()) ** 2])
    solution, *_ = np.linalg.lstsq(basis, d, rcond=None)
    explained = 1.0 - np.var(d - basis @ solution) / np.var(d)
    return float(solution[3]), float(explained)


@pytest.mark.slow
def test_the_page_shows_the_live_station_and_its_drifting_map(tmp_path: Path) -> None:
    config = _drifting_station(tmp_path)
    stdout, stderr = tmp_path / "results.jsonl", tmp_path / "stderr.txt"
    with stdout.open("w") as out, stderr.open("w") as err:
        process = subprocess.Popen([sys.executable, "-m", "wavestack.cli", "run", "--config", str(config), "--web",
                                    "--web-port", "0", "--json", "--duration", "240"], stdout=out, stderr=err)
    try:
        url = _wait_for("the URL on stderr", lambda: re.search(r"^web view: (http://127\.0\.0\.1:\d+/)$",
                                                               stderr.read_text(), re.M), 60).group(1)
        with chromium_page(tmp_path / "profile") as page:
            page.goto(url)
            read = lambda: page.evaluate(_READ_PAGE)  # noqa: E731
            # both maps from the configured fitter (not the qr stand-in of the first results): one basis
            first = _wait_for("a map of a valid result", lambda: (s := read())["state"] == "running" and s["src"]
                              and s["shown"] != "-" and "fallback" not in s["fitter"] and s)
            results = _results(stdout)
            _check_numbers(first, results)
            start = _result_of_map(first)
            t0 = results[start]["exposure_time_ns"]

            def drifted() -> dict | None:  # a newer map, exposed >= 4 s later (0.2 waves of defocus)
                s = read()
                index = _result_of_map(s)
                r = _results(stdout).get(index)
                return s if r is not None and r["exposure_time_ns"] - t0 >= 4e9 else None

            second = _wait_for("a map 4 s of drift later", drifted)
            results = _results(stdout)
            _check_numbers(second, results)
            ARTEFACT.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(ARTEFACT), full_page=True)
            process.send_signal(signal.SIGTERM)
            _wait_for("the stopped state", lambda: read()["state"] == "stopped", 60)
        assert process.wait(timeout=60) == 0, stderr.read_text()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    # the map changed as the surface drifted: a paraboloid growing as Noll 4 (sqrt(3)(2 r^2 - 1)) grows
    end = _result_of_map(second)
    a, b = _map_values(first), _map_values(second)
    change = b - a
    change -= np.nanmean(change)  # each set's piston is its own
    c_a, c_b = np.array(results[start]["coefficients"]), np.array(results[end]["coefficients"])
    defocus_change = c_b[3] - c_a[3]
    assert defocus_change > 0.1, (start, end, defocus_change)  # the optic did drift (0.05 waves/s, >= 4 s)
    expected_rms = float(np.sqrt(np.sum((c_b[3:] - c_a[3:]) ** 2)))  # rms-normalised terms beyond the tilts
    shown_rms = float(np.sqrt(np.nanmean(change ** 2)))
    # the colour scale quantises to (vmax - vmin) / 255, ~0.01 waves here; block means and the fit's
    # mapped (not exactly orthonormal) basis allow the rest: within 35 %
    assert 0.65 < shown_rms / expected_rms < 1.35, (shown_rms, expected_rms)
    curvature, explained = _drift_fit(change)
    assert curvature > 0 and explained > 0.8, (curvature, explained)
    assert ARTEFACT.stat().st_size > 10_000
