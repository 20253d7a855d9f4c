"""The simulated controller's histories are bounded, so a long simulated run's memory stays flat."""

from __future__ import annotations

from wavestack.simulators.mdt693b.device import COMMAND_HISTORY, RECEIVED_HISTORY, MDT693BDevice


def test_command_and_byte_histories_keep_only_the_newest() -> None:
    device = MDT693BDevice()
    n = COMMAND_HISTORY + 2_000
    for i in range(n):
        device.feed(f"xvoltage={i % 100}\r".encode())
    assert device.commands_received == n
    assert len(device.commands) == COMMAND_HISTORY and device.commands[-1] == f"xvoltage={(n - 1) % 100}"
    received = device.received
    assert len(received) <= RECEIVED_HISTORY and received.endswith(f"xvoltage={(n - 1) % 100}\r".encode())
    for _ in range(RECEIVED_HISTORY // 8):
        device.feed(b"xvoltage?\r")
    assert len(device.received) <= RECEIVED_HISTORY and len(device._received) <= 2 * RECEIVED_HISTORY
