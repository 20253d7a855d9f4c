"""What a simulated USB3 Vision camera is built from and what it reports, besides the wire.

:class:`U3VSimSettings` is the power-on configuration, :class:`FrameRenderer` the callable that
draws each frame, :class:`U3VSimFaults` the switches tests flip to inject faults, and
:class:`U3VSimCounters` the simulator's own bookkeeping.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal, Protocol

from numpy.typing import NDArray

from wavestack.simulators.u3v.descriptors import SIM_PRODUCT_ID, SIM_VENDOR_ID
from wavestack.simulators.u3v.stream_device import PIXEL_FORMATS

MAX_IMAGE_SIDE = 16384
CorruptionKind = Literal["magic", "block_id", "size"]


class FrameRenderer(Protocol):
    """Produces the pixels of one frame and its ground truth."""

    def __call__(self, block_id: int, device_time_ns: int, exposure_us: float) -> tuple[NDArray[Any], Any]:
        """Pixels, shape (height, width), uint8 or uint16 counts in the streamed format's range
        (larger values saturate), and any ground-truth object kept for :meth:`.camera.SimulatedU3VCamera.truth`.
        ``device_time_ns`` is the exposure start on the device clock."""
        ...


@dataclass(frozen=True)
class U3VSimSettings:
    """Power-on configuration of a simulated camera.

    Attributes
    ----------
    serial, model, manufacturer
        USB string descriptors and ABRM strings (ASCII).
    width, height
        Power-on image size, pixels.
    pixel_format
        Power-on PixelFormat.
    frame_rate_hz
        Free-run frame rate.
    exposure_us
        Power-on ExposureTime, microseconds.
    zipped_xml
        Serve the GenICam file zipped (manifest file type 1) instead of plain XML.
    max_response_time_ms
        ABRM maximum device response time.
    max_transfer_bytes
        SBRM maximum command and acknowledge transfer lengths (whole packets, bytes).
    payload_alignment_log2
        SIRM SI info alignment: transfer sizes must be multiples of 2**n bytes.
    vendor_id, product_id
        USB ids (pid.codes test ids by default).
    vendor, vendor_xml
        A real camera's register map (a name of :data:`wavestack.simulators.genicam.PERSONALITIES`)
        and the path of its GenApi XML: the camera then serves that XML and those registers
        instead of its own; None keeps the simulator's own XML.
    """

    serial: str = "WS-SIM-0001"
    model: str = "WaveCam U3V-Sim"
    width: int = 640
    height: int = 480
    pixel_format: Literal["Mono8", "Mono12", "Mono16"] = "Mono12"
    frame_rate_hz: float = 30.0
    exposure_us: float = 1000.0
    zipped_xml: bool = False
    max_response_time_ms: int = 200
    manufacturer: str = "wavestack"
    max_transfer_bytes: int = 1024
    payload_alignment_log2: int = 0
    vendor_id: int = SIM_VENDOR_ID
    product_id: int = SIM_PRODUCT_ID
    vendor: str | None = None
    vendor_xml: str | None = None

    def __post_init__(self) -> None:
        if (self.vendor is None) != (self.vendor_xml is None):
            raise ValueError("U3VSimSettings: vendor and vendor_xml go together (a register map and its XML)")
        if not (1 <= self.width <= MAX_IMAGE_SIDE and 1 <= self.height <= MAX_IMAGE_SIDE):
            raise ValueError(f"U3VSimSettings: width/height must lie in 1..{MAX_IMAGE_SIDE}, "
                             f"got {self.width} x {self.height}")
        if self.pixel_format not in PIXEL_FORMATS:
            raise ValueError(f"U3VSimSettings: pixel_format must be one of {sorted(PIXEL_FORMATS)}, "
                             f"got {self.pixel_format!r}")
        if not (math.isfinite(self.frame_rate_hz) and 0 < self.frame_rate_hz <= 100_000):
            raise ValueError(f"U3VSimSettings: frame_rate_hz must lie in (0, 1e5], got {self.frame_rate_hz}")
        if not (math.isfinite(self.exposure_us) and 1.0 <= self.exposure_us <= 10_000_000.0):
            raise ValueError(f"U3VSimSettings: exposure_us must lie in [1, 1e7], got {self.exposure_us}")
        if not 64 <= self.max_transfer_bytes <= 0xFFFF + 12:
            raise ValueError(f"U3VSimSettings: max_transfer_bytes must lie in 64..65547, "
                             f"got {self.max_transfer_bytes}")
        if not 0 <= self.payload_alignment_log2 <= 16:
            raise ValueError(f"U3VSimSettings: payload_alignment_log2 must lie in 0..16, "
                             f"got {self.payload_alignment_log2}")
        if not 0 <= self.max_response_time_ms <= 0xFFFF_FFFF:
            raise ValueError("U3VSimSettings: max_response_time_ms must fit in u32")


@dataclass
class U3VSimFaults:
    """Fault switches; tests flip them on the camera's ``faults`` instance.

    Attributes
    ----------
    timeout_reads
        The next N stream reads wait their whole timeout, then time out (an infinite timeout, 0,
        times out at once). Nothing is consumed.
    partial_transfer
        The next payload transfer arrives cut to half its length (the rest is lost on the bus; the
        trailer still reports the full payload). One-shot.
    stall_next
        The next stream read stalls the stream endpoint: EPIPE until ``clear_halt(0x82)``, which
        also drops the block in flight. One-shot.
    corrupt_leader, corrupt_trailer
        The next leader / trailer is damaged: ``"magic"`` (bad magic), ``"block_id"`` (id + 1) or
        ``"size"`` (cut to 20 bytes while its size field keeps the full length). One-shot.
    pending_ack_ms
        While > 0, every acknowledged command is first answered by PENDING_ACK advertising this
        many ms, and its real acknowledge becomes readable half that time later.
    stream_paused
        While True the stream sends nothing (every stream read waits its timeout): a camera that
        stalls without going away. The control channel still answers; a block in flight waits.
    """

    timeout_reads: int = 0
    partial_transfer: bool = False
    stall_next: bool = False
    corrupt_leader: CorruptionKind | None = None
    corrupt_trailer: CorruptionKind | None = None
    pending_ack_ms: int = 0
    stream_paused: bool = False


@dataclass(frozen=True)
class U3VSimCounters:
    """Snapshot of the simulator's bookkeeping (cumulative over acquisitions and plug cycles).

    ``frames_produced >= blocks_sent + frames_skipped``; the difference is frames completed but
    not yet taken by the host.
    """

    frames_produced: int
    frames_skipped: int
    blocks_sent: int
    triggers_ignored: int
    commands_received: int
