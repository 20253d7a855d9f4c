"""USB over TCP: a pyusb backend that reaches a USB bus served by another process (``usbtcp://``).

``protocol`` encodes requests and frames and checks replies (pure), ``backend`` is the pyusb
backend on the one byte link (:class:`UsbTcpBackend`). The server side is the simulators'
:mod:`wavestack.simulators.usb_tcp`.
"""

from __future__ import annotations

from wavestack.drivers.usb_tcp.backend import UsbTcpBackend, parse_usbtcp_url

__all__ = ["UsbTcpBackend", "parse_usbtcp_url"]
