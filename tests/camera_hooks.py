"""A simulated camera's hooks reduced to accepting everything: for fuzzing its register map alone."""

from __future__ import annotations

from wavestack.simulators.u3v.register_map import GenCPStatus


class AcceptingHooks:
    """The camera behind the registers: every feature reads 1 (ExposureTime 1.0), every write succeeds.

    Parameters
    ----------
    time_ns : int
        What the device clock reads, ns.
    """

    def __init__(self, time_ns: int = 0) -> None:
        self._time_ns = time_ns

    def device_time_ns(self) -> int:
        return self._time_ns

    def get_feature(self, name: str) -> int | float:
        return 1.0 if name == "ExposureTime" else 1

    def set_feature(self, name: str, value: int | float) -> GenCPStatus:
        return GenCPStatus.SUCCESS

    def get_stream_register(self, offset: int) -> int:
        return 0

    def set_stream_register(self, offset: int, value: int) -> GenCPStatus:
        return GenCPStatus.SUCCESS
