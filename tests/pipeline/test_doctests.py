"""The Examples sections of the pipeline's main public faces run, and show what they say.

Each module listed must hold at least one example (a module whose examples were all deleted
would otherwise pass silently), and every example must give the output written under it.
"""

from __future__ import annotations

import doctest
import importlib

import numpy as np
import pytest

MODULES_WITH_EXAMPLES = (
    "wavestack.pipeline.zernike.indices",  # noll_to_nm, index_to_nm
    "wavestack.pipeline.zernike.conversion",  # convert_coefficients
    "wavestack.pipeline.zernike.names",  # mode_name
    "wavestack.pipeline.aperture.region",  # Aperture.from_mask
    "wavestack.pipeline.fit.build",  # build_fitter
    "wavestack.pipeline.fit.annulus",  # annulus_obscuration
    "wavestack.pipeline.fit.map_domain",  # map_domain
    "wavestack.pipeline.fit.run_fill",  # fitted_runs, fill_runs
    "wavestack.pipeline.fit.moment_chunks",  # ChunkedPass
    "wavestack.pipeline.fit.run_moments",  # RunPass
    "wavestack.pipeline.fit.run_refit",  # RunRefit
    "wavestack.pipeline.phase.psi.algorithms",  # phase_from_frames
    "wavestack.pipeline.instrument.fitter_source",  # build_configured, SyncFitterSource
    "wavestack.pipeline.instrument.quality",  # mark_quality
    "wavestack.pipeline.instrument.statistics",  # robust_pv
    "wavestack.pipeline.instrument.phase_shifting",  # PhaseShiftingProcessor
    "wavestack.pipeline.instrument.carrier",  # CarrierProcessor
    "wavestack.pipeline.instrument.streams",  # measure_set
    "wavestack.pipeline.shack_hartmann.lattice",  # LensletLattice
    "wavestack.pipeline.shack_hartmann.lattice_detection",  # detect_lattice
    "wavestack.pipeline.shack_hartmann.lit",  # lit_lenslets
    "wavestack.pipeline.instrument.shack_hartmann",  # ShackHartmannProcessor
    "wavestack.pipeline.formats.fourd",  # read_4d
    "wavestack.pipeline.formats.measured",  # read_measured_map
    "wavestack.pipeline.polishing.tif",  # ToolInfluence
    "wavestack.pipeline.polishing.removal",  # removal_nm
    "wavestack.pipeline.polishing.extension",  # dwell_grid
    "wavestack.pipeline.polishing.fft_solver",  # solve_dwell_fft
    "wavestack.pipeline.polishing.lsq_solver",  # solve_dwell_lsq
    "wavestack.pipeline.polishing.grid",  # GridFrame
    "wavestack.pipeline.polishing.limits",  # MachineLimits
    "wavestack.pipeline.polishing.path",  # PointLattice, raster_order, spiral_order
    "wavestack.pipeline.polishing.feed",  # feed_profile
    "wavestack.pipeline.polishing.machine_program",  # MachineProgram
    "wavestack.pipeline.polishing.program",  # plan_program
    "wavestack.pipeline.polishing.program_checks",  # check_program
    "wavestack.pipeline.surface.tolerance",  # parse_form_tolerance, FormTolerance
    "wavestack.pipeline.surface.form",  # FormAnalyzer
    "wavestack.pipeline.surface.radial",  # RadialModel
    "wavestack.pipeline.surface.robust_pv",  # RobustPVAnalyzer
    "wavestack.pipeline.surface.psd",  # surface_psd
    "wavestack.pipeline.surface.power_law",  # fit_power_law
    "wavestack.pipeline.surface.slope",  # slope_maps
    "wavestack.pipeline.surface.areal_filter",  # filter_surface, parse_areal_filter
    "wavestack.pipeline.surface.compliance",  # check_form
    "wavestack.pipeline.averaging.robust",  # robust_average
    "wavestack.pipeline.calibration.rotation",  # rotate_coefficients, solve_rotation_test
    "wavestack.pipeline.surface.figures",  # SurfaceAnalyzer
)


@pytest.mark.parametrize("name", MODULES_WITH_EXAMPLES)
def test_examples_run_and_match(name: str) -> None:
    module = importlib.import_module(name)
    finder = doctest.DocTestFinder(exclude_empty=True)
    tests = [test for test in finder.find(module, name) if test.examples]
    assert tests, f"{name} has no Examples section any more"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    with np.printoptions(legacy=False):
        for test in tests:
            runner.run(test)
    outcome = runner.summarize(verbose=False)
    assert outcome.attempted > 0
    assert outcome.failed == 0, f"{outcome.failed} of {outcome.attempted} examples failed in {name}"


def test_a_wrong_example_is_caught() -> None:
    """The check above can fail: an example with a wrong expected output is counted as failed."""
    parser = doctest.DocTestParser()
    test = parser.get_doctest(
        ">>> from wavestack.pipeline import noll_to_nm\n>>> noll_to_nm(4)\n(2, 2)\n",
        {}, "wrong", "wrong.py", 0,
    )
    runner = doctest.DocTestRunner()
    runner.run(test, out=lambda text: None)
    assert runner.summarize(verbose=False).failed == 1
