"""PI hexapod controllers (C-887 class) and PI stages speaking GCS 2.0 ASCII over TCP or RS-232.

``protocol`` encodes commands and frames and parses replies (pure, fuzzable), ``error_codes``
holds the controller error codes with PI's meanings and :class:`GcsError`, ``limits`` the move
limits and the pure check every move passes, ``link`` the byte link (TCP port 50000 or a
``serial_for_url`` port), ``driver`` knows what to ask (:class:`PIHexapod`). The axes are
configuration: a hexapod's X Y Z U V W by default, a two-axis field stage's ``"1" "2"`` as well.
"""

from __future__ import annotations

from wavestack.drivers.pi_gcs.driver import HEXAPOD_AXES, HexapodMove, PIHexapod
from wavestack.drivers.pi_gcs.error_codes import GCS_ERRORS, STOPPED_BY_COMMAND, GcsError, error_meaning
from wavestack.drivers.pi_gcs.limits import HexapodLimits, move_refusals
from wavestack.drivers.pi_gcs.link import DEFAULT_PORT

__all__ = [
    "DEFAULT_PORT",
    "GCS_ERRORS",
    "HEXAPOD_AXES",
    "STOPPED_BY_COMMAND",
    "GcsError",
    "HexapodLimits",
    "HexapodMove",
    "PIHexapod",
    "error_meaning",
    "move_refusals",
]
