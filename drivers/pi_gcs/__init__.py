"""PI hexapod controllers (C-887 class) and PI stages speaking GCS 2.0 ASCII over TCP or RS-232.

``protocol`` encodes commands and frames and parses replies (pure, fuzzable), ``error_codes``
holds the controller error codes with PI's meanings and :class:`GcsError`, ``limits`` the move
limits and the pure check every move passes, ``driver`` knows what to ask (:class:`PIHexapod`) on
the one byte link (:mod:`wavestack.drivers.link`: TCP port 50000 or a ``serial_for_url`` port). The axes are
configuration: a hexapod's X Y Z U V W by default, a two-axis field stage's ``"1" "2"`` as well.

Pose convention (the driver sends and reads the controller's numbers and computes no rotation;
this records what they mean). PI's hexapod manuals [1]_ say: translations X Y Z are in the
spatially fixed coordinate system; rotations U V W (deg) are about axes that meet at the pivot
point (``SPI``) and "always move together with the platform"; "a given rotation in space is
calculated from the individual rotations in the order U -> V -> W". Rotations about moving axes,
U first, compose as R = Rx(U) Ry(V) Rz(W) (equivalently: W about the fixed Z, then V about the
fixed Y, then U about the fixed X), which is *not* Rz(W) Ry(V) Rx(U). The simulator and the
telescope model should check their rule against this.

References
----------
.. [1] Physik Instrumente, MS207E "H-820 Hexapod Microrobot" v2.3.0, section 3.7.4 "Motion"
   (p. 13); the same text in MS202E "H-850" (p. 14) and MS222E "H-845" (p. 23). The C-887
   controller's coordinate systems: PI technical note C887T0007.
"""

from __future__ import annotations

from wavestack.drivers.pi_gcs.driver import DEFAULT_PORT, HEXAPOD_AXES, HexapodMove, PIHexapod
from wavestack.drivers.pi_gcs.error_codes import GCS_ERRORS, STOPPED_BY_COMMAND, GcsError, error_meaning
from wavestack.drivers.pi_gcs.limits import HexapodLimits, move_refusals

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
