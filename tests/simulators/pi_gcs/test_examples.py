"""The Examples sections of the GCS simulator's modules run as doctests."""

from __future__ import annotations

import doctest
from types import ModuleType

import pytest

from wavestack.simulators.pi_gcs import controller, framing, motion, pose, pty_serial, server, settings


@pytest.mark.parametrize("module", [controller, framing, motion, pose, pty_serial, server, settings], ids=lambda m: m.__name__)
def test_examples_run(module: ModuleType) -> None:
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0, f"{module.__name__} has no Examples to run"
    assert result.failed == 0
