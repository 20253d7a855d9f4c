"""Hypothesis settings for the property tests of the parsers we own.

Each parser test asks for a number of examples that keeps CI quick (a few hundred), drawn the same
way on every run (the ``ci`` profile is derandomised); the ``long`` profile, loaded with
``pytest --hypothesis-profile=long``, draws afresh and raises every one of them to 10,000
(see the README, "Faults and safety"). Tests that fuzz a parser use :func:`fuzz_settings`
instead of writing ``max_examples`` themselves, so the long profile reaches them all.
"""

from __future__ import annotations

from hypothesis import HealthCheck, settings

LONG_EXAMPLES = 10_000

# "ci", loaded by default (tests/conftest.py): the same examples on every run, so a red CI is a
# regression and never the luck of the draw; "long" draws afresh each run, to explore.
settings.register_profile("ci", deadline=None, database=None, print_blob=True, derandomize=True)
settings.register_profile("long", deadline=None, database=None, max_examples=LONG_EXAMPLES,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("ci")  # pytest --hypothesis-profile=long loads "long" over it


def fuzz_settings(ci_examples: int = 300) -> settings:
    """Settings for one parser property test: ``ci_examples`` by default, 10,000 under ``long``.

    Parameters
    ----------
    ci_examples : int
        Examples per run in the default (CI) profile.

    Returns
    -------
    hypothesis.settings
        No deadline (the machine is shared), no example database, and ``ci_examples``
        examples, or the loaded profile's count when that is the long profile's (or more).
    """
    loaded = settings.default
    examples = loaded.max_examples if loaded.max_examples >= LONG_EXAMPLES else ci_examples
    return settings(loaded, deadline=None, database=None, max_examples=examples)
