"""The Examples sections of the TMA modules run as doctests, and can fail."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = ("wavestack.pipeline.telescope.design", "wavestack.pipeline.telescope.pose", "wavestack.pipeline.telescope.model",
           "wavestack.pipeline.telescope.reference", "wavestack.pipeline.telescope.sensitivity")


@pytest.mark.parametrize("name", MODULES)
def test_examples_run(name: str) -> None:
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0, f"{name} has no Examples to run"
    assert result.failed == 0
