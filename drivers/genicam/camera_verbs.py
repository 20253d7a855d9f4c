"""The public verbs every GenICam camera driver offers, whatever its transport.

:class:`GenICamCamera` is the common face of :class:`~wavestack.drivers.u3v.U3VCamera` and
:class:`~wavestack.drivers.gige.GigECamera`: reading the image size, pixel format and exposure,
setting them (validated before anything is sent), the trigger, any feature by name, and reading
frames from its ring. A driver supplies its
:class:`~wavestack.drivers.genicam.camera_features.CameraFeatures`, its default timeout, its frame
ring and whether it is acquiring or closed.
"""

from __future__ import annotations

import math
import time

from wavestack.drivers._checks import check_timeout
from wavestack.drivers.errors import DeviceDisconnected, LimitError, ProtocolError
from wavestack.drivers.frames import Frame
from wavestack.drivers.genicam.camera_features import CameraFeatures
from wavestack.drivers.genicam.node_map import NodeMap
from wavestack.drivers.ring import FrameRing

#: Pixel formats the drivers' stream decoders deliver (PFNC names; Mono12 unpacked in 16 bits).
DECODABLE_FORMATS = ("Mono8", "Mono12", "Mono16")


class GenICamCamera:
    """Feature verbs on top of a driver's :meth:`_camera_features`, and the frame consumer's verbs on its
    ring (see the module description)."""

    _name: str
    _timeout_s: float
    _acquiring: bool
    _closed: bool
    _ring: FrameRing[Frame]

    @property
    def name(self) -> str:
        """Device name used in messages (address or USB ids, model, serial)."""
        return self._name

    def loss_mark(self) -> int:
        """Frames reported lost so far: take it before a trigger, pass it to :meth:`read_frame`."""
        return self._ring.losses

    def discard_pending(self) -> int:
        """Drop the frames waiting in the ring (counted dropped); returns how many."""
        return self._ring.discard_pending()

    def read_frame(self, timeout_s: float, *, since_loss: int | None = None) -> Frame:
        """The next frame by the ring's policy.

        ``since_loss``: a :meth:`loss_mark`; a block the stream discarded since then raises
        :class:`~wavestack.drivers.ring.FrameLost` at once (a triggered frame that will not come).

        Raises
        ------
        DeviceTimeout
            No frame within ``timeout_s`` (e.g. waiting for a trigger, or not started).
        DeviceDisconnected
            The camera went away (after the pending frames are read) or was closed (at once:
            closing is final, frames still pending are not delivered).
        """
        if self._closed:
            raise DeviceDisconnected(self._name, "camera closed")
        return self._ring.get(timeout_s, fail_after_loss=since_loss)

    def _camera_features(self) -> CameraFeatures:
        raise NotImplementedError

    def _deadline(self, timeout_s: float | None) -> float:
        timeout = self._timeout_s if timeout_s is None else timeout_s
        check_timeout(timeout)
        return time.monotonic() + timeout

    @property
    def node_map(self) -> NodeMap:
        """The device's GenICam node map (every feature its XML describes)."""
        return self._camera_features().node_map

    @property
    def width(self) -> int:
        """Image width, pixels (read from the device)."""
        return int(self._camera_features().get("Width", self._deadline(None)))  # type: ignore[arg-type]

    @property
    def height(self) -> int:
        """Image height, pixels (read from the device)."""
        return int(self._camera_features().get("Height", self._deadline(None)))  # type: ignore[arg-type]

    @property
    def pixel_format(self) -> str:
        """Pixel format name from the XML's enumeration (``"Mono8"``, ``"Mono12"``, ...), read from the device."""
        return str(self._camera_features().get("PixelFormat", self._deadline(None)))

    @property
    def exposure_us(self) -> float:
        """Exposure time, µs (read from the device)."""
        return float(self._camera_features().get("ExposureTime", self._deadline(None)))  # type: ignore[arg-type]

    def set_exposure_us(self, exposure_us: float, timeout_s: float) -> None:
        """Set the exposure time ``exposure_us``, µs, waiting at most ``timeout_s`` s per register access.

        Raises ``ValueError`` when it is not finite or <= 0 and ``LimitError`` outside the device's
        Min/Max (nothing sent in either case).
        """
        if not (math.isfinite(exposure_us) and exposure_us > 0):
            raise ValueError(f"exposure_us must be finite and > 0, got {exposure_us}")
        self._camera_features().set("ExposureTime", float(exposure_us), self._deadline(timeout_s))

    def set_pixel_format(self, name: str, timeout_s: float) -> None:
        """Select ``"Mono8"``, ``"Mono12"`` or ``"Mono16"``; only while not acquiring.

        Raises
        ------
        ValueError
            A format the stream decoder does not deliver, or acquisition is running (nothing sent).
        LimitError
            The device does not offer this format now (nothing sent).
        """
        if name not in DECODABLE_FORMATS:
            raise ValueError(f"pixel format {name!r} is not supported; expected one of {list(DECODABLE_FORMATS)}")
        if self._acquiring:
            raise ValueError(f"{self._name}: stop acquisition before changing the pixel format")
        features = self._camera_features()
        deadline = self._deadline(timeout_s)
        offered = features.info("PixelFormat", deadline).entries
        if name not in offered:
            raise LimitError(self._name, f"PixelFormat {name!r} not offered; device has {sorted(offered)}")
        features.set("PixelFormat", name, deadline)

    def set_trigger_mode(self, on: bool, timeout_s: float) -> None:
        """Software-triggered (``True``: one frame per :meth:`trigger_software`) or free-run (``False``)."""
        self._camera_features().set_trigger_mode(on, self._deadline(timeout_s))

    def trigger_software(self, timeout_s: float) -> None:
        """Execute TriggerSoftware (one frame when the trigger mode is on)."""
        self._camera_features().execute("TriggerSoftware", self._deadline(timeout_s))

    def read_feature(self, name: str, timeout_s: float | None = None) -> int | float | bool | str | bytes:
        """Read any feature the device's XML describes, e.g. ``PayloadSize`` or ``DeviceVendorName``.

        Integers come as int, floats as float, enumerations as their entry name, strings as text.

        Raises
        ------
        ProtocolError
            The XML does not describe ``name``, it is not readable now, or the device refused the read.
        """
        return self._camera_features().get(name, self._deadline(timeout_s))

    def write_feature(self, name: str, value: int | float | bool | str, timeout_s: float) -> None:
        """Write any writable feature (validated against the device's limits first; nothing sent otherwise).

        Raises
        ------
        LimitError
            Outside the device's limits or not an entry.
        ProtocolError
            Not described, not writable now, or refused by the device.
        """
        self._camera_features().set(name, value, self._deadline(timeout_s))

    def set_device_user_id(self, name: str, timeout_s: float) -> None:
        """Write ``DeviceUserID``, the user-chosen name the camera keeps (SFNC Device Control).

        Raises ``ValueError`` for a name not ASCII (nothing sent), ``ProtocolError`` when the XML
        has no writable ``DeviceUserID`` or the device refused it.
        """
        if not name.isascii():
            raise ValueError(f"DeviceUserID {name!r}: expected ASCII text")
        try:
            self._camera_features().set("DeviceUserID", name, self._deadline(timeout_s))
        except ProtocolError as exc:
            if "characters" in exc.detail:
                raise ValueError(f"DeviceUserID {name!r}: {exc.detail}") from None
            raise
