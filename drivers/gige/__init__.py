"""GigE Vision camera driver: GVCP control (UDP 3956) and a GVSP stream, over the standard library's sockets.

Pure modules, fuzzable:

* :mod:`~wavestack.drivers.gige.gvcp` -- commands, acknowledges, DISCOVERY, bootstrap registers, the file URL.
* :mod:`~wavestack.drivers.gige.gvsp` -- packets, the image leader, block assembly with resend requests.

and the I/O around them:

* :mod:`~wavestack.drivers.gige.control` -- the control channel (retries, PENDING_ACK, stale acknowledges
  discarded) and the register port the GenICam node map reads through.
* :mod:`~wavestack.drivers.gige.discovery` -- DISCOVERY and ``gige://`` URLs.
* :mod:`~wavestack.drivers.gige.stream` -- the stream socket and its thread.
* :mod:`~wavestack.drivers.gige.driver` with :class:`GigECamera`::

    with GigECamera.open("gige://192.168.10.20", timeout_s=2.0) as camera:
        camera.start()
        frame = camera.read_frame(timeout_s=1.0)
"""

from __future__ import annotations

from wavestack.drivers.gige.discovery import GigEUrl, discover, parse_gige_url
from wavestack.drivers.gige.driver import DEFAULT_PACKET_SIZE, GigECamera, GigECounters
from wavestack.drivers.gige.gvcp import GVCP_PORT, DeviceInfo

__all__ = ["DEFAULT_PACKET_SIZE", "GVCP_PORT", "DeviceInfo", "GigECamera", "GigECounters", "GigEUrl", "discover",
           "parse_gige_url"]
