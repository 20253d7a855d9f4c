"""Helpers of the end-to-end polishing tests (tests/polish, tests/cli/test_polish.py): the simulated polishing station (full size or small), a session, a campaign."""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

from wavestack.config.polishing import DEFAULT_POLISHING_CONFIG, PolishingConfig, parse_polishing_config
from wavestack.polish.loop import CampaignSummary, LoopOptions, PolishingLoop
from wavestack.polish.recorder import CampaignRecorder
from wavestack.polish.session import PolishingSession, open_session

DEFAULT_TEXT = DEFAULT_POLISHING_CONFIG.read_text(encoding="utf-8")
# The default station at half the pixels: 256 x 256 at 0.5 mm per pixel (the same 100 mm optic,
# the same 4 mm tool), for the fault tests, which need a working loop but not its accuracy.
SMALL = {
    "width = 512": "width = 256", "height = 512": "height = 256",
    "centre_px = [255.5, 255.5]": "centre_px = [127.5, 127.5]", "radius_px = 200.0": "radius_px = 100.0",
    "pixel_mm = 0.25": "pixel_mm = 0.5", "step_px = 4": "step_px = 2", "averaged_results = 8": "averaged_results = 4",
}


def polishing_text(small: bool = False, **replace: str) -> str:
    """The default polishing station's text, optionally small, with ``old=new`` replacements (keys as ``a__b``)."""
    text = DEFAULT_TEXT
    for old, new in (SMALL if small else {}).items():
        assert old in text, old
        text = text.replace(old, new)
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new)
    return text


def polishing_config(tmp_path: Path, small: bool = False, replacements: dict[str, str] | None = None
                     ) -> PolishingConfig:
    text = polishing_text(small, **(replacements or {}))
    return parse_polishing_config(text, source=str(tmp_path / "polishing.toml"))


class CountingLink:
    """The session's link, counting every job it announces and started; ``damage`` may spoil the file first.

    A test double at the loop's ``link`` seam (the network share between host and machine), not a
    patch: every call goes to the real link.
    """

    def __init__(self, link: Any, damage: Callable[[Any], Any] | None = None) -> None:
        self._link = link
        self._damage = damage
        self.loads: Counter[int] = Counter()
        self.starts: Counter[int] = Counter()

    def load_job(self, receipt: Any, job_id: int, timeout_s: float = 2.0) -> Any:
        self.loads[job_id] += 1
        if self._damage is not None:
            receipt = self._damage(receipt) or receipt
        return self._link.load_job(receipt, job_id, timeout_s=timeout_s)

    def start_job(self, job_id: int, timeout_s: float = 2.0) -> Any:
        self.starts[job_id] += 1
        return self._link.start_job(job_id, timeout_s=timeout_s)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._link, name)


@contextmanager
def polishing_session(config: PolishingConfig) -> Iterator[PolishingSession]:
    with ExitStack() as stack:
        yield open_session(config, stack)


def run_campaign(session: PolishingSession, *, max_runs: int, target_rms_nm: float = 5.0, link: Any = None,
                 record: Path | None = None, on_event: Callable[[str, str], None] | None = None,
                 stop: threading.Event | None = None) -> tuple[CampaignSummary, list[tuple[str, str]]]:
    """One campaign on ``session``; returns its summary and every (phase, reason) it went through."""
    events: list[tuple[str, str]] = []

    def note(phase: str, reason: str) -> None:
        events.append((phase, reason))
        if on_event is not None:
            on_event(phase, reason)

    recorder = None
    if record is not None:
        camera = session.devices.camera
        recorder = CampaignRecorder(record, (camera.height, camera.width), session.config.text,
                                    {"pixel_mm": session.config.polishing.pixel_mm})
    loop = PolishingLoop(session.config, LoopOptions(target_rms_nm, max_runs, session.config.polishing.solver),
                         link=link or session.link, maps=session.maps, tif=session.tif,
                         job_folder=session.job_folder, stop=stop or threading.Event(), recorder=recorder,
                         target_nm=session.target_nm, on_event=note)
    try:
        summary = loop.run()
    finally:
        if recorder is not None:
            recorder.close("test", "", -1)
    return summary, events


def when_machine_has_points(session: PolishingSession, action: Callable[[], None], *, points: int = 1,
                            timeout_s: float = 60.0) -> threading.Thread:
    """A thread that runs ``action`` once the machine reports ``points`` points done (poll with a deadline)."""
    machine = session.devices.plc_simulator.machine

    def watch() -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if machine.snapshot().points_done >= points:
                action()
                return
            time.sleep(0.005)

    thread = threading.Thread(target=watch, name="fault-injector")
    thread.start()
    return thread
