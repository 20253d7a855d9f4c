"""Hypothesis settings for the property tests of the parsers we own.

Each parser test asks for a number of examples that keeps CI quick (a few hundred); the ``long``
profile, loaded with ``pytest --hypothesis-profile=long``, raises every one of them to 10,000
(see the README, "Faults and safety"). Tests that fuzz a parser use :func:`fuzz_settings`
instead of writing ``max_examples`` themselves, so the long profile reaches them all.
"""

from __future__ import annotations

from hypothesis import HealthCheck, settings

LONG_EXAMPLES = 10_000

settings.register_profile("ci", deadline=None, database=None, print_blob=True)
settings.register_profile("long", deadline=None, database=None, max_examples=LONG_EXAMPLES,
                          suppress_health_check=[HealthCheck.too_slow])


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
