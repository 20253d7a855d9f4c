"""The camera features a station uses, on any transport's node map, each call within a deadline.

:class:`CameraFeatures` is what a camera driver (USB3 Vision, GigE Vision) asks of its device's
XML: image size, pixel format, exposure, the software trigger, acquisition start and stop, and
the transport-layer lock a GenTL producer sets around an acquisition. Names follow SFNC 2.x; a
camera that still describes its exposure by the SFNC 1.x name ``ExposureTimeAbs`` (older GigE
Vision firmware, e.g. Basler's ace) is served through that name.

The transport's port holds the deadline of the register accesses a feature call makes; the lock
here keeps one feature call (and its deadline) at a time.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Protocol

from wavestack.drivers.errors import DeviceError, ProtocolError
from wavestack.drivers.genicam.node_map import FeatureInfo, NodeMap
from wavestack.drivers.genicam.registers import Port

#: The station's features, each with the names a camera may describe it by (SFNC 2.x first).
STATION_FEATURES: dict[str, tuple[str, ...]] = {
    "Width": ("Width",), "Height": ("Height",), "PixelFormat": ("PixelFormat",),
    "ExposureTime": ("ExposureTime", "ExposureTimeAbs"), "TriggerMode": ("TriggerMode",),
    "TriggerSoftware": ("TriggerSoftware",), "AcquisitionStart": ("AcquisitionStart",),
    "AcquisitionStop": ("AcquisitionStop",),
}
REQUIRED = ("Width", "Height", "PixelFormat", "AcquisitionStart", "AcquisitionStop")


class DeadlinePort(Port, Protocol):
    """A register port whose accesses must finish by ``deadline`` (``time.monotonic()``, s)."""

    deadline: float


class CameraFeatures:
    """A camera's station features through its node map and register port.

    Parameters
    ----------
    node_map
        The device's node map, already attached to ``port``.
    port
        The port the node map reads and writes through; its deadline is set per call.
    """

    def __init__(self, node_map: NodeMap, port: DeadlinePort) -> None:
        self.node_map = node_map
        self._port = port
        self._lock = threading.RLock()

    @property
    def device(self) -> str:
        return self.node_map.device

    def name_of(self, feature: str) -> str | None:
        """The name this camera describes a station feature by, or None when it resolves under none."""
        return next((name for name in STATION_FEATURES.get(feature, (feature,)) if name in self.node_map), None)

    def __contains__(self, feature: object) -> bool:
        return isinstance(feature, str) and self.name_of(feature) is not None

    def _name(self, feature: str) -> str:
        name = self.name_of(feature)
        if name is None:
            names = " or ".join(STATION_FEATURES.get(feature, (feature,)))
            raise ProtocolError(self.device, f"feature {names} is not described in the device's GenICam XML "
                                             f"(or does not resolve through its nodes)")
        return name

    def require(self) -> None:
        """Check the features every acquisition needs resolve (at open).

        Raises
        ------
        ProtocolError
            One is missing, naming it.
        """
        for feature in REQUIRED:
            self._name(feature)

    @contextmanager
    def within(self, deadline: float) -> Iterator[NodeMap]:
        """The node map, with every register access of the block bounded by ``deadline``."""
        with self._lock:
            self._port.deadline = deadline
            yield self.node_map

    def get(self, feature: str, deadline: float) -> int | float | bool | str | bytes:
        with self.within(deadline) as node_map:
            return node_map.get(self._name(feature))

    def info(self, feature: str, deadline: float) -> FeatureInfo:
        with self.within(deadline) as node_map:
            return node_map.info(self._name(feature))

    def set(self, feature: str, value: int | float | bool | str, deadline: float) -> None:
        with self.within(deadline) as node_map:
            node_map.set(self._name(feature), value)

    def execute(self, feature: str, deadline: float) -> None:
        with self.within(deadline) as node_map:
            node_map.execute(self._name(feature))

    def set_trigger_mode(self, on: bool, deadline: float) -> None:
        """Software-triggered frames (``TriggerSelector`` = ``FrameStart`` first, when the camera has a
        selector) or free run."""
        with self.within(deadline) as node_map:
            if "TriggerSelector" in node_map and node_map.access("TriggerSelector") in ("RW", "WO"):
                if "FrameStart" in node_map.info("TriggerSelector").entries:
                    node_map.set("TriggerSelector", "FrameStart")
            node_map.set(self._name("TriggerMode"), "On" if on else "Off")

    def lock_transport_layer(self, deadline: float) -> None:
        """Before AcquisitionStart, as a GenTL producer does (SFNC): AcquisitionMode Continuous, then
        TLParamsLocked 1, each where the camera describes it and allows it now."""
        with self.within(deadline) as node_map:
            if "AcquisitionMode" in node_map and node_map.access("AcquisitionMode") in ("RW", "WO"):
                if "Continuous" in node_map.info("AcquisitionMode").entries:
                    node_map.set("AcquisitionMode", "Continuous")
            if "TLParamsLocked" in node_map:
                node_map.set("TLParamsLocked", 1)

    def unlock_transport_layer(self, deadline: float) -> None:
        """TLParamsLocked back to 0 after AcquisitionStop; a failure is returned to be logged, not raised."""
        with self.within(deadline) as node_map:
            if "TLParamsLocked" in node_map:
                node_map.set("TLParamsLocked", 0)

    def forget_cache(self) -> None:
        """Drop cached register values (after a reconnect or a device reset)."""
        with self._lock:
            self.node_map.forget_cache()


def unlock_quietly(features: CameraFeatures, deadline: float) -> DeviceError | None:
    """:meth:`CameraFeatures.unlock_transport_layer`, returning the device error instead of raising it."""
    try:
        features.unlock_transport_layer(deadline)
    except DeviceError as exc:
        return exc
    return None
