"""What a simulated GigE Vision camera is built from, and the switches tests flip to inject faults."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

MAX_IMAGE_SIDE = 16384


@dataclass(frozen=True)
class GigESimSettings:
    """Power-on configuration of a simulated GigE Vision camera.

    Attributes
    ----------
    serial, model, manufacturer
        What DISCOVERY and the bootstrap registers report (ASCII; serial up to 16 characters).
    width, height, pixel_format, frame_rate_hz, exposure_us
        Power-on image, free-run rate and ExposureTime (µs).
    host, port
        Where the GVCP server listens: 127.0.0.1 and an ephemeral port in tests; a real camera
        answers on port 3956 (what ``arv-tool`` and other GigE Vision software talk to).
    heartbeat_timeout_ms
        Control privilege is released when no command came for this long.
    link_rate_mbit_s
        Streaming pace: packets leave no faster than this (1000: a GigE link).
    vendor, vendor_xml
        A real camera's register map (:data:`wavestack.simulators.genicam.PERSONALITIES`) and its XML
        path, served instead of the simulator's own XML.
    """

    serial: str = "WS-GIGE-0001"
    model: str = "WaveCam GigE-Sim"
    manufacturer: str = "wavestack"
    width: int = 640
    height: int = 480
    pixel_format: Literal["Mono8", "Mono12", "Mono16"] = "Mono12"
    frame_rate_hz: float = 30.0
    exposure_us: float = 1000.0
    host: str = "127.0.0.1"
    port: int = 0
    heartbeat_timeout_ms: int = 3000
    link_rate_mbit_s: float = 1000.0
    vendor: str | None = None
    vendor_xml: str | None = None

    def __post_init__(self) -> None:
        if not (1 <= self.width <= MAX_IMAGE_SIDE and 1 <= self.height <= MAX_IMAGE_SIDE):
            raise ValueError(f"GigESimSettings: width/height must lie in 1..{MAX_IMAGE_SIDE}")
        if not (math.isfinite(self.frame_rate_hz) and 0 < self.frame_rate_hz <= 10_000):
            raise ValueError(f"GigESimSettings: frame_rate_hz must lie in (0, 1e4], got {self.frame_rate_hz}")
        if not (self.serial.isascii() and 0 < len(self.serial) <= 16):
            raise ValueError(f"GigESimSettings: serial {self.serial!r} must be 1..16 ASCII characters")
        if not 0 <= self.port <= 65535 or not 100 <= self.heartbeat_timeout_ms <= 600_000:
            raise ValueError("GigESimSettings: port 0..65535, heartbeat_timeout_ms 100..600000")
        if not (math.isfinite(self.link_rate_mbit_s) and self.link_rate_mbit_s > 0):
            raise ValueError("GigESimSettings: link_rate_mbit_s must be > 0")
        if (self.vendor is None) != (self.vendor_xml is None):
            raise ValueError("GigESimSettings: vendor and vendor_xml go together (a register map and its XML)")


@dataclass
class GigESimFaults:
    """Fault switches; tests flip them on the camera's ``faults`` instance.

    Attributes
    ----------
    packet_loss
        Fraction of GVSP packets (first sends and resends alike) not sent, drawn from a seeded
        generator (``loss_seed``).
    reorder
        Send each pair of data packets swapped.
    silent
        Answer nothing at all (GVCP and stream): a camera whose cable was pulled or which hung.
    wrong_ack_id
        Answer the next N commands with an acknowledge carrying another id (a stale reply).
    oversized_packet
        Send the next block's first data packet padded to 9100 bytes (larger than any negotiated size).
    stream_paused
        Send no stream packets (control still answers).
    """

    packet_loss: float = 0.0
    loss_seed: int = 1
    reorder: bool = False
    silent: bool = False
    wrong_ack_id: int = 0
    oversized_packet: bool = False
    stream_paused: bool = False
