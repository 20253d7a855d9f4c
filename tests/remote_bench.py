"""The real-bench configuration pointed at a remote alignment bench: the shipped example with its addresses replaced."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "config" / "tma-alignment-remote.toml"
EXAMPLE_STATION = REPO / "config" / "tma-alignment-remote-station.toml"


def addresses(lines: list[str]) -> dict[str, str]:
    """``sim align-bench``'s announcements -> {"hexapod": url, "field_stage": url, "camera": url, "piezo": url}."""
    found = {}
    for line in lines:
        name, kind, where, *rest = line.split()
        if kind == "pty":
            found[name] = where
        elif name == "camera" or name == "piezo":
            found[name] = rest[0]
        else:
            found[name] = f"tcp://{where}"
    return found


def write_real_config(folder: Path, urls: dict[str, str], **align: object) -> Path:
    """Write the example (and its station file) into ``folder`` with ``urls`` and ``[align]`` overrides."""
    station = EXAMPLE_STATION.read_text(encoding="utf-8")
    station = re.sub(r'(?m)^url = "usbtcp://[^"]*"', f'url = "{urls["camera"]}"', station)
    station = re.sub(r'(?m)^url = "socket://[^"]*"', f'url = "{urls["piezo"]}"', station)
    (folder / EXAMPLE_STATION.name).write_text(station, encoding="utf-8")
    text = EXAMPLE.read_text(encoding="utf-8")
    text = text.replace('url = "tcp://127.0.0.1:50000"', f'url = "{urls["hexapod"]}"')
    text = text.replace('url = "tcp://127.0.0.1:50001"', f'url = "{urls["field_stage"]}"')
    for key, value in align.items():
        shown = str(value).lower() if isinstance(value, bool) else repr(value) if isinstance(value, str) else value
        text, count = re.subn(rf"(?m)^{key} = .*$", f"{key} = {shown}", text)
        if not count:
            text = text.replace("[align]\n", f"[align]\n{key} = {shown}\n", 1)
    path = folder / EXAMPLE.name
    path.write_text(text, encoding="utf-8")
    return path
