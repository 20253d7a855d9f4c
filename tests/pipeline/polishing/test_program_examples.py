"""The Examples sections of the machine-program modules run and show what they say.

(The same check as tests/pipeline/test_doctests.py, for this topic's modules; each must hold at
least one example, so deleting them all is noticed.)
"""

from __future__ import annotations

import doctest
import importlib

import numpy as np
import pytest

MODULES = (
    "wavestack.pipeline.polishing.grid",  # GridFrame
    "wavestack.pipeline.polishing.limits",  # MachineLimits
    "wavestack.pipeline.polishing.path",  # PointLattice, raster_order, spiral_order
    "wavestack.pipeline.polishing.feed",  # feed_profile
    "wavestack.pipeline.polishing.machine_program",  # MachineProgram
    "wavestack.pipeline.polishing.program",  # plan_program
    "wavestack.pipeline.polishing.program_checks",  # check_program
)


@pytest.mark.parametrize("name", MODULES)
def test_examples_run_and_match(name: str) -> None:
    module = importlib.import_module(name)
    tests = [test for test in doctest.DocTestFinder(exclude_empty=True).find(module, name) if test.examples]
    assert tests, f"{name} has no Examples section any more"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    with np.printoptions(legacy=False):
        for test in tests:
            runner.run(test)
    outcome = runner.summarize(verbose=False)
    assert outcome.attempted > 0
    assert outcome.failed == 0, f"{outcome.failed} of {outcome.attempted} examples failed in {name}"
