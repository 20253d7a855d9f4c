"""The Examples sections of the simulated machine's modules run as doctests."""

from __future__ import annotations

import doctest
from types import ModuleType

import pytest

from wavestack.simulators.plc import job_state, machine_tif


@pytest.mark.parametrize("module", [job_state, machine_tif], ids=lambda m: m.__name__)
def test_examples_run(module: ModuleType) -> None:
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0, f"{module.__name__} has no Examples to run"
    assert result.failed == 0
