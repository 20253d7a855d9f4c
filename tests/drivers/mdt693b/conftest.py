"""Fixtures of the MDT693B driver tests: a simulated controller served over ``sim://`` or a pseudo-terminal."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import ExitStack

import pytest

from wavestack.simulators import attach_simulated_device, register_serial_simulators
from wavestack.simulators.mdt693b import MDT693BDevice, PtyBridge


@pytest.fixture(autouse=True)
def _sim_urls() -> None:
    register_serial_simulators()


@pytest.fixture(params=["sim", "pty"])
def transport(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.fixture
def connect(transport: str) -> Iterator[Callable[[MDT693BDevice], str]]:
    """Serve a device on the transport under test; returns the URL a driver opens."""
    with ExitStack() as stack:
        def serve(device: MDT693BDevice) -> str:
            if transport == "sim":
                name = f"dev{id(device)}"
                stack.enter_context(attach_simulated_device(name, device))
                return f"sim://{device.personality.model.lower()}/{name}"
            return stack.enter_context(PtyBridge(device)).port_path

        yield serve
