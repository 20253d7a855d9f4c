"""The Examples sections of the web view's modules run as doctests, and can fail."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = ("wavestack.web.view", "wavestack.web.render", "wavestack.web.slots", "wavestack.web.feed",
           "wavestack.web.server", "wavestack.cli.web_view", "wavestack.align.history")


@pytest.mark.parametrize("name", MODULES)
def test_examples_run(name: str) -> None:
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0, f"{name} has no Examples to run"
    assert result.failed == 0
