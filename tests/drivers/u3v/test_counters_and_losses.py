"""Camera counters over the camera's life (never backwards across a reconnect), and lost triggered frames.

A damaged block in trigger mode is reported to a reader that asked (``since_loss``) at once, as
:class:`~wavestack.drivers.ring.FrameLost`, instead of after its whole timeout.
"""

from __future__ import annotations

import time

import pytest

from wavestack.drivers.errors import DeviceDisconnected
from wavestack.drivers.ring import FrameLost
from wavestack.drivers.u3v import U3VCamera
from wavestack.simulators.u3v import SimulatedU3VCamera, SimulatedUsbBackend, U3VSimSettings

TIMEOUT_S = 5.0  # generous: only bounds a hang


def _sim() -> SimulatedU3VCamera:
    import numpy as np

    def render(block_id: int, device_time_ns: int, exposure_us: float):
        pixels = np.full((16, 24), block_id % 4096, dtype=np.uint16)
        return pixels, None

    return SimulatedU3VCamera(U3VSimSettings(serial="SIM-C", width=24, height=16, frame_rate_hz=200.0), render)


def test_counters_carry_on_across_an_unplug_and_reopen() -> None:
    device = _sim()
    with U3VCamera.open(backend=SimulatedUsbBackend([device]), timeout_s=TIMEOUT_S) as camera:
        camera.start()
        for _ in range(5):
            camera.read_frame(TIMEOUT_S)
        device.unplug()
        with pytest.raises(DeviceDisconnected):
            while True:  # drain what was pending, then the unplug
                camera.read_frame(TIMEOUT_S)
        before = camera.counters()
        camera.stop()
        device.replug()
        camera.reopen(timeout_s=TIMEOUT_S)
        after_reopen = camera.counters()
        camera.start()
        for _ in range(3):
            camera.read_frame(TIMEOUT_S)
        after = camera.counters()
        camera.stop()
    for earlier, later in ((before, after_reopen), (after_reopen, after)):
        assert later.acquired >= earlier.acquired and later.delivered >= earlier.delivered
        assert later.dropped >= earlier.dropped
    assert after.delivered == before.delivered + 3
    assert camera.present() is False  # closed: never present again
    for c in (before, after_reopen, after):
        assert c.acquired == c.delivered + c.dropped + c.pending


def test_a_damaged_triggered_block_is_reported_at_once_not_after_the_timeout() -> None:
    device = _sim()
    with U3VCamera.open(backend=SimulatedUsbBackend([device]), timeout_s=TIMEOUT_S) as camera:
        camera.set_trigger_mode(True, TIMEOUT_S)
        camera.start()
        mark = camera.loss_mark()
        camera.trigger_software(TIMEOUT_S)
        camera.read_frame(TIMEOUT_S, since_loss=mark)  # a whole frame
        device.faults.corrupt_leader = "magic"
        mark = camera.loss_mark()
        camera.trigger_software(TIMEOUT_S)
        started = time.monotonic()
        with pytest.raises(FrameLost):
            camera.read_frame(30.0, since_loss=mark)
        assert time.monotonic() - started < 10.0  # far less than the 30 s asked for
        mark = camera.loss_mark()
        camera.trigger_software(TIMEOUT_S)
        camera.read_frame(TIMEOUT_S, since_loss=mark)  # the next trigger brings a whole frame again
        camera.stop()
