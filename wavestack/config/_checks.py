"""Checks the configuration schemas and the station share (written once here)."""

from __future__ import annotations

from typing import Final

#: Bits per pixel of each camera pixel format the station supports.
BIT_DEPTH: Final = {"Mono8": 8, "Mono12": 12, "Mono16": 16}
