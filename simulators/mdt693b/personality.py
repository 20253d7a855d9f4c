"""What makes one simulated MDT693B / MDT694B / MDT693A differ from another, and its fault switches.

Plain values shared by the device's two command sets (:mod:`~wavestack.simulators.mdt693b.device`,
:mod:`~wavestack.simulators.mdt693b.compatibility`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = ["AxisState", "MDT693BFaults", "MDT693BPersonality"]

_SWITCH_SETTINGS_V = (75.0, 100.0, 150.0)


@dataclass
class MDT693BFaults:
    """Fault switches of one simulated controller (flip them from a test; read on every byte).

    Attributes
    ----------
    silent
        The controller is hung: it reads commands but neither executes nor answers them.
    garbage
        Commands execute, but each reply is replaced by random non-ASCII bytes and the prompt.
    split_replies
        Replies arrive in three pieces ~10 ms apart (a USB-serial adapter flushing mid-reply).
    unplugged
        The cable is out: the transport raises or closes instead of delivering bytes.
    """

    silent: bool = False
    garbage: bool = False
    split_replies: bool = False
    unplugged: bool = False


@dataclass(frozen=True)
class MDT693BPersonality:
    """What distinguishes one controller (model, firmware, settings) from another.

    Attributes
    ----------
    model
        ``"MDT693B"`` (axes x, y, z), ``"MDT694B"`` (axis x) or ``"MDT693A"`` (axes x, y, z; the
        older controller, which speaks only the MDT693A command set).
    echo
        Echo at power-on.
    prompt
        ``">"`` (firmware 1.10) or ``"*"`` (firmware 1.05).
    firmware, serial_number, friendly_name
        Reported by ``id?``.
    vlimit_v
        Front-panel limit switch at power-on: 75, 100 or 150 V.
    decimals
        Decimals of a voltage reply (2 on firmware 1.10, 1 on 1.05).
    compatibility_mode
        MDT693A compatibility mode at power-on (the controller keeps the setting); always on for an
        MDT693A.
    """

    model: Literal["MDT693B", "MDT694B", "MDT693A"] = "MDT693B"
    echo: bool = True
    prompt: Literal[">", "*"] = ">"
    firmware: str = "1.10"
    serial_number: str = "SIM-000001"
    friendly_name: str = "simulated"
    vlimit_v: float = 150.0
    decimals: int = 2
    compatibility_mode: bool = False

    def __post_init__(self) -> None:
        if self.vlimit_v not in _SWITCH_SETTINGS_V:
            raise ValueError(f"vlimit_v must be one of {_SWITCH_SETTINGS_V}, got {self.vlimit_v!r}")
        if self.prompt not in (">", "*"):
            raise ValueError(f"prompt must be '>' or '*', got {self.prompt!r}")
        if self.model not in ("MDT693B", "MDT694B", "MDT693A"):
            raise ValueError(f"model must be 'MDT693B', 'MDT694B' or 'MDT693A', got {self.model!r}")

    @property
    def axes(self) -> tuple[str, ...]:
        """Output axes of the model."""
        return ("x",) if self.model == "MDT694B" else ("x", "y", "z")

    @property
    def compatibility_model(self) -> str:
        """The older model the compatibility mode imitates: ``"MDT693A"`` or ``"MDT694A"``."""
        return self.model[:-1] + "A"

    def id_text(self) -> str:
        """The ``id?`` (``I``) reply body, lines separated by CR (an MDT693A has no serial or name line)."""
        names = [] if self.model == "MDT693A" else [f"Serial#:{self.serial_number}",
                                                      f"Friendly Name:{self.friendly_name}"]
        lines = [f"Model {self.model} Piezo Control Module", f"Firmware Version: {self.firmware}",
                 "Voltage Range: 0V to 150V", *names, "Thorlabs, Inc. Newton, NJ 07860", "www.thorlabs.com", ""]
        return "\r".join(lines)


@dataclass
class AxisState:
    """One output: its voltage and its limits, V."""

    volts: float = 0.0
    min_v: float = 0.0
    max_v: float = 150.0

    def set_limit(self, which: Literal["min", "max"], volts: float) -> None:
        """Move the lower or upper limit, never past the other one (the output itself stays)."""
        if which == "min":
            self.min_v = min(volts, self.max_v)
        else:
            self.max_v = max(volts, self.min_v)
