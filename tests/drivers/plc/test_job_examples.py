"""The Examples sections of the job modules (host side) run as doctests."""

from __future__ import annotations

import doctest
from types import ModuleType

import pytest

from wavestack.drivers.plc import job_file, jobs


@pytest.mark.parametrize("module", [jobs, job_file], ids=lambda m: m.__name__)
def test_examples_run(module: ModuleType) -> None:
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0, f"{module.__name__} has no Examples to run"
    assert result.failed == 0
