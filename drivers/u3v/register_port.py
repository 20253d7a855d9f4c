"""The camera's register space over its GenCP control channel, as the GenICam node map's port."""

from __future__ import annotations

from wavestack.drivers.u3v.control import ControlChannel


class GenCPPort:
    """Register reads and writes for the node map, each bounded by :attr:`deadline`.

    Parameters
    ----------
    control
        The camera's control channel (READMEM/WRITEMEM, split into chunks it allows).
    """

    def __init__(self, control: ControlChannel) -> None:
        self._control = control
        self.deadline = 0.0  # time.monotonic() by which an access must be acknowledged; set per feature call

    def read(self, address: int, length: int) -> bytes:
        """``length`` bytes at ``address`` (DeviceTimeout, ProtocolError, DeviceDisconnected as the channel)."""
        return self._control.read(address, length, self.deadline, f"register 0x{address:X}")

    def write(self, address: int, data: bytes) -> None:
        """Store ``data`` at ``address``."""
        self._control.write(address, data, self.deadline, f"register 0x{address:X}")
