"""Simulated PI GCS 2.0 controller: the C-887 hexapod (X Y Z U V W) or, with other axes, a PI stage.

Written from PI's documents, never from wavestack's driver (a shared parser would share its bugs):

- :mod:`.framing`: the wire rules (LF lines, single-byte ``#5``/``#7``/``#24``, multi-line answers
  with a space before every LF but the last), bytes -> events, answers -> bytes;
- :mod:`.controller`: :class:`GcsController`, the commands and the device state;
- :mod:`.motion`: the platform moving at its velocity in simulated time (computed from the clock);
- :mod:`.pose`: :class:`SimPose` snapshots and PI's pose convention (:func:`platform_transform`);
- :mod:`.faults`: :class:`GcsSimFaults` (error on the next command, stuck axis, slow move,
  dropped connection, split or truncated answers);
- :mod:`.server`: :class:`HexapodSimulator`, the TCP server (``wavestack sim hexapod``);
- :mod:`.pty_serial`: :class:`GcsPtyBridge`, the same controller on a pseudo-terminal (RS-232);
- :mod:`.codes`: PI's GCS error numbers it sets.
"""

from __future__ import annotations

from wavestack.simulators.pi_gcs.codes import GCS_ERRORS
from wavestack.simulators.pi_gcs.controller import GcsController
from wavestack.simulators.pi_gcs.faults import GcsSimFaults, ReplyFault
from wavestack.simulators.pi_gcs.framing import Delivery, LineAssembler, format_reply
from wavestack.simulators.pi_gcs.motion import Segment, plan_segment
from wavestack.simulators.pi_gcs.pty_serial import GcsPtyBridge
from wavestack.simulators.pi_gcs.pose import SimPose, platform_transform, rotation_matrix
from wavestack.simulators.pi_gcs.server import DEFAULT_GCS_PORT, HexapodSimulator
from wavestack.simulators.pi_gcs.settings import HEXAPOD_AXES, HexapodSimSettings

__all__ = [
    "DEFAULT_GCS_PORT",
    "Delivery",
    "GCS_ERRORS",
    "GcsController",
    "GcsPtyBridge",
    "GcsSimFaults",
    "HEXAPOD_AXES",
    "HexapodSimSettings",
    "HexapodSimulator",
    "LineAssembler",
    "ReplyFault",
    "Segment",
    "SimPose",
    "format_reply",
    "plan_segment",
    "platform_transform",
    "rotation_matrix",
]
