"""The Examples sections of the alignment modules run as doctests, and can fail."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = ("wavestack.align.state", "wavestack.align.terms", "wavestack.align.estimator", "wavestack.align.correction",
           "wavestack.align.recorder", "wavestack.simulators.align_bench", "wavestack.align.station_source")


@pytest.mark.parametrize("name", MODULES)
def test_examples_run(name: str) -> None:
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0, f"{name} has no Examples to run"
    assert result.failed == 0
