"""The Examples sections of the polishing loop's modules run as doctests, and can fail."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = ("wavestack.polish.state", "wavestack.polish.measurement", "wavestack.polish.job_checks",
           "wavestack.polish.run_record", "wavestack.polish.recorder", "wavestack.polish.history")


@pytest.mark.parametrize("name", MODULES)
def test_examples_run(name: str) -> None:
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0, f"{name} has no Examples to run"
    assert result.failed == 0
