"""The simulated PLC's histories are bounded (a long run must not grow: issue 13's soak crept ~5 MB/min)."""

from __future__ import annotations

import numpy as np

from wavestack.simulators.plc import polishing
from wavestack.simulators.plc.polishing import PolishingStation, RemovalCommand


def test_the_polishing_model_remembers_only_the_newest_ids_and_a_wrapped_id_polishes_again() -> None:
    station = PolishingStation((10.0, 20.0, 30.0, 40.0), noise_nm=0.0, efficiency_spread=0.0, seed=1)
    removal = (0.0, 0.0, 0.0, 0.001)
    for command_id in range(1, polishing.REMEMBERED_COMMANDS + 50):
        station.apply(RemovalCommand(command_id, removal, 1))
    assert len(station._done) == polishing.REMEMBERED_COMMANDS  # noqa: SLF001 (the bound itself)
    before = station.surface_nm
    station.apply(RemovalCommand(polishing.REMEMBERED_COMMANDS + 49, removal, 1))  # a retry: once per id
    np.testing.assert_array_equal(station.surface_nm, before)
    station.apply(RemovalCommand(1, removal, 1))  # id 1 again after the 16-bit id wrapped: a new command
    assert station.surface_nm[3] < before[3]
