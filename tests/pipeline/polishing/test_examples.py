"""The Examples sections of the polishing topic's public names run, and show what they say."""

from __future__ import annotations

import doctest
import importlib

import numpy as np
import pytest

MODULES_WITH_EXAMPLES = (
    "wavestack.pipeline.polishing.tif",  # ToolInfluence
    "wavestack.pipeline.polishing.removal",  # removal_nm
    "wavestack.pipeline.polishing.extension",  # dwell_grid
    "wavestack.pipeline.polishing.fft_solver",  # solve_dwell_fft
    "wavestack.pipeline.polishing.lsq_solver",  # solve_dwell_lsq
)


@pytest.mark.parametrize("name", MODULES_WITH_EXAMPLES)
def test_examples_run_and_match(name: str) -> None:
    module = importlib.import_module(name)
    tests = [test for test in doctest.DocTestFinder(exclude_empty=True).find(module, name) if test.examples]
    assert tests, f"{name} has no Examples section any more"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    with np.printoptions(legacy=False):
        for test in tests:
            runner.run(test, out=lambda text: None)
    outcome = runner.summarize(verbose=False)
    assert outcome.attempted > 0
    assert outcome.failed == 0, f"{outcome.failed} of {outcome.attempted} examples failed in {name}"
