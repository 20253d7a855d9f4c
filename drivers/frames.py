"""What a frame source delivers: camera frames and Shack-Hartmann slope frames.

Frames are plain values (frozen dataclasses holding an ndarray), so the pipeline never needs to
know which device or protocol produced them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray


def _frozen_metadata(metadata: Mapping[str, Any] | None) -> Mapping[str, Any]:
    return MappingProxyType(dict(metadata or {}))


@dataclass(frozen=True)
class Frame:
    """One camera image.

    Attributes
    ----------
    frame_id
        The device's frame (block) id; consecutive frames differ by one, so a gap is a drop.
    host_time_ns
        ``time.time_ns()`` on the host when the frame was complete.
    device_timestamp
        The device's own timestamp (ticks of its clock, 0 if it has none).
    pixels
        Image, shape (height, width), dtype uint8 or uint16 (Mono12 is delivered in uint16).
    metadata
        Read-only extras, e.g. ``pzt_commanded_v``, ``pzt_readback_v``, ``pixel_format``.
    """

    frame_id: int
    host_time_ns: int
    device_timestamp: int
    pixels: NDArray[np.generic]
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "metadata", _frozen_metadata(self.metadata))
        if np.ndim(self.pixels) != 2:
            raise ValueError(f"Frame {self.frame_id}: pixels must be 2-D, got shape {np.shape(self.pixels)}")


@dataclass(frozen=True)
class SlopeFrame:
    """One Shack-Hartmann measurement as slopes (a sensor that computes its own centroids).

    Attributes
    ----------
    frame_id, host_time_ns, device_timestamp
        As in :class:`Frame`.
    slope_x, slope_y
        Wavefront slopes per lenslet, shape (n_lenslets,), in the units named by
        ``metadata["slope_units"]`` (radians of wavefront tilt unless stated).
    valid
        Boolean, shape (n_lenslets,): lenslets with enough light.
    metadata
        Read-only extras.
    """

    frame_id: int
    host_time_ns: int
    device_timestamp: int
    slope_x: NDArray[np.float64]
    slope_y: NDArray[np.float64]
    valid: NDArray[np.bool_]
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "metadata", _frozen_metadata(self.metadata))
        shapes = {np.shape(self.slope_x), np.shape(self.slope_y), np.shape(self.valid)}
        if len(shapes) != 1 or np.ndim(self.slope_x) != 1:
            raise ValueError(f"SlopeFrame {self.frame_id}: slope_x, slope_y and valid must be 1-D of one length, "
                             f"got shapes {sorted(shapes)}")


@runtime_checkable
class FrameSource(Protocol):
    """Anything that delivers camera frames (a driver, a simulator, a recording)."""

    def start(self) -> None:
        """Begin acquisition."""

    def stop(self) -> None:
        """End acquisition; idempotent."""

    def read_frame(self, timeout_s: float) -> Frame:
        """The next frame; raises ``DeviceTimeout`` after ``timeout_s`` seconds."""


@runtime_checkable
class SlopeSource(Protocol):
    """Anything that delivers Shack-Hartmann slope frames."""

    def start(self) -> None:
        """Begin acquisition."""

    def stop(self) -> None:
        """End acquisition; idempotent."""

    def read_slopes(self, timeout_s: float) -> SlopeFrame:
        """The next slope frame; raises ``DeviceTimeout`` after ``timeout_s`` seconds."""
