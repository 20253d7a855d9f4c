"""Simulated GigE Vision camera: GVCP and GVSP on UDP, the same optic and fault switches as the USB3 one.

:class:`SimulatedGigECamera` serves its own GenICam XML (big-endian registers) or a real vendor's
(:data:`wavestack.simulators.genicam.PERSONALITIES`, e.g. the Basler ace); the device side is
written from the GigE Vision text, never from the driver's parser. ``wavestack sim gige`` runs
one on its own.
"""

from __future__ import annotations

from wavestack.simulators.gige.camera import SimulatedGigECamera
from wavestack.simulators.gige.settings import GigESimFaults, GigESimSettings

__all__ = ["GigESimFaults", "GigESimSettings", "SimulatedGigECamera"]
