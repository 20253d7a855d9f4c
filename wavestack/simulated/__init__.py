"""The simulator starter: the one place that builds and starts simulated devices from a configuration.

A station file whose URLs say ``sim://`` gets its simulators started here
(:func:`start_simulated_station`: the test optic and camera, the piezo, the PLC with its polishing
machine), an alignment bench with ``[align] simulated = true`` its two PI controllers and its
as-built telescope (:func:`start_align_bench`), a ``sim://`` rotation stage its GCS controller coupled
to the station's part (:func:`start_rotation_stage`), a simulated calibration ball its seating
(:func:`ball_seating`), and the ``wavestack sim ...`` commands theirs; the
configuration's simulator tables become the simulators' own settings in
:mod:`~wavestack.simulated.settings`. Nothing else in ``wavestack/`` imports ``wavestack.simulators``:
the station imports this package only when a configured URL is ``sim://``, and the alignment
session only for a simulated bench, so a real bench never loads a simulator.
"""

from __future__ import annotations

from wavestack.simulated.align_bench import align_bench, reference_tilt_step, start_align_bench, unknown_mount
from wavestack.simulated.settings import (
    as_simulator,
    camera_settings,
    hexapod_settings,
    machine_settings,
    piezo_device,
    plc_layout,
    polishing_machine,
    polishing_station,
)
from wavestack.simulated.ball import ball_seating, reference_truth_errors
from wavestack.simulated.rotation_stage import SimulatedRotationStage, start_rotation_stage
from wavestack.simulated.station import SimulatedStation, simulated_interferometer, start_simulated_station

__all__ = ["SimulatedRotationStage", "SimulatedStation", "ball_seating", "reference_truth_errors", "start_rotation_stage", "align_bench", "as_simulator", "camera_settings", "hexapod_settings", "machine_settings",
           "piezo_device", "plc_layout", "polishing_machine", "polishing_station", "reference_tilt_step",
           "simulated_interferometer", "start_align_bench", "start_simulated_station", "unknown_mount"]
