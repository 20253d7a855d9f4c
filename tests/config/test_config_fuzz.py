"""Property test: any TOML station file becomes a configuration or one ConfigError line naming the key.

Documents are drawn from the schema: a shipped station file (interferometer, Shack-Hartmann or the
hardware example) with one to four edits, each on a key or table the schema knows (or an unknown
one): a valid value for the key's type and bounds, a value of another type, a boolean, nan or
infinity, a huge number, an array of the wrong length, a table, a deleted key or table. The text
is written out as TOML (nan and inf literals included) and parsed by ``parse_station_config``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import tomllib
import types
import typing
from pathlib import Path
from typing import Any

import pytest
from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from wavestack.config import DEFAULT_CONFIG
from wavestack.config.camera import CameraSettings, CameraSimulatorSettings
from wavestack.config.plc import PlcLinkSettings, PolishingModelSettings
from wavestack.config.processing import ProcessingSettings
from wavestack.config.pzt import PiezoSettings, PiezoSimulatorSettings
from wavestack.config.schema import ConfigError
from wavestack.config.shack_hartmann import ShackHartmannSettings
from wavestack.config.station import OutputSettings, StationSettings, parse_station_config
from wavestack.simulators.bench import PiezoCoupling
from wavestack.simulators import SurfaceSettings
from wavestack.simulators.optic import OpticSettings
from wavestack.simulators.spots import LensletArraySettings

ROOT = Path(__file__).resolve().parents[2]
BASES = [tomllib.loads(path.read_text(encoding="utf-8")) for path in (
    DEFAULT_CONFIG, ROOT / "config" / "shack-hartmann.toml", ROOT / "config" / "shack-hartmann-hex.toml",
    ROOT / "config" / "station-hardware.example.toml")]
SCHEMAS: dict[tuple[str, ...], type] = {
    ("station",): StationSettings, ("processing",): ProcessingSettings, ("camera",): CameraSettings,
    ("camera", "simulator"): CameraSimulatorSettings, ("pzt",): PiezoSettings, ("pzt", "simulator"): PiezoSimulatorSettings,
    ("plc",): PlcLinkSettings, ("plc", "simulator", "polishing"): PolishingModelSettings, ("outputs",): OutputSettings,
    ("optic",): OpticSettings, ("bench",): PiezoCoupling, ("shack_hartmann",): ShackHartmannSettings,
    ("lenslets",): LensletArraySettings, ("optic", "surface"): SurfaceSettings,
}
SOURCE = "fuzz.toml"


def _fields() -> list[tuple[tuple[str, ...], str, Any, dict[str, Any]]]:
    """(table path, key, type hint, setting metadata) of every key of every table, nested schemas included."""
    found = []
    pending = list(SCHEMAS.items())
    while pending:
        path, schema = pending.pop()
        hints = typing.get_type_hints(schema)
        for field in dataclasses.fields(schema):
            hint = hints[field.name]
            if dataclasses.is_dataclass(hint):
                pending.append(((*path, field.name), hint))
            found.append((path, field.name, hint, dict(field.metadata or {})))
    return found


FIELDS = _fields()

HOSTILE = st.one_of(
    st.booleans(), st.sampled_from([math.nan, math.inf, -math.inf, 0, -1, 0.0, -0.0, 1e300, -1e300]),
    st.integers(min_value=-(10 ** 400), max_value=10 ** 400), st.integers(-(2 ** 64), 2 ** 64),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=12),
    st.sampled_from(["", "sim://u3v", "usb://", "/dev/../etc/passwd", "/dev/ttyUSB0", "COM3", "tcp://h:1"]),
    st.lists(st.one_of(st.integers(-5, 400), st.floats(-1e3, 1e3), st.booleans()), max_size=6),
    st.dictionaries(st.sampled_from(["a", "url", "kind"]), st.integers(0, 3), max_size=2),
)


def valid_value(hint: Any, meta: dict[str, Any]) -> st.SearchStrategy[Any]:
    """Values of the key's type inside its bounds (cross-table rules may still refuse them)."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return valid_value(next(a for a in args if a is not type(None)), meta)
    if origin is typing.Literal:
        return st.sampled_from(args)
    if meta.get("choices"):
        return st.sampled_from(meta["choices"])
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return st.lists(valid_value(args[0], meta), max_size=8)
        return st.tuples(*(valid_value(a, meta) for a in args)).map(list)
    low, high = meta.get("minimum"), meta.get("maximum")
    if hint is bool:
        return st.booleans()
    if hint is int:
        return st.integers(int(math.ceil(low)) if low is not None else -(2 ** 63),
                           int(high) if high is not None else 2 ** 63 - 1)
    if hint is float:
        return st.floats(low, high, allow_nan=False, allow_infinity=False)
    return st.text(max_size=8)


@st.composite
def edit(draw: st.DrawFn) -> tuple[str, tuple[str, ...], str, Any]:
    """One edit: ("set", table, key, value), ("delete", table, key, None), or a table-level edit."""
    kind = draw(st.sampled_from(["valid", "valid", "hostile", "wrong-length", "delete", "unknown-key", "table"]))
    path, key, hint, meta = draw(st.sampled_from(FIELDS))
    if kind == "valid":
        return "set", path, key, draw(valid_value(hint, meta))
    if kind == "hostile":
        return "set", path, key, draw(HOSTILE)
    if kind == "wrong-length":
        return "set", path, key, draw(st.lists(st.floats(-10, 10), min_size=0, max_size=40))
    if kind == "delete":
        return "delete", path, key, None
    if kind == "unknown-key":
        return "set", path, draw(st.sampled_from(["vlimt", "urll", "steps", "x"])), draw(HOSTILE)
    table = draw(st.sampled_from([*(p[:1] for p in SCHEMAS), ("simulator",), ("unknown_table",)]))
    return draw(st.sampled_from(["delete", "set"])), table[:-1], table[-1], draw(HOSTILE)


def apply(document: dict[str, Any], change: tuple[str, tuple[str, ...], str, Any]) -> None:
    action, path, key, value = change
    table = document
    for name in path:
        if not isinstance(table.get(name), dict):
            table[name] = {}
        table = table[name]
    if action == "delete":
        table.pop(key, None)
    else:
        table[key] = value


def toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)  # nan, inf, -inf and 1e+300 are TOML too
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, dict):
        return "{" + ", ".join(f"{toml_key(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    return "[" + ", ".join(toml_value(v) for v in value) + "]"


def toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def toml_text(document: dict[str, Any], path: tuple[str, ...] = ()) -> str:
    scalars = {k: v for k, v in document.items() if not isinstance(v, dict)}
    tables = {k: v for k, v in document.items() if isinstance(v, dict)}
    lines = [f"[{'.'.join(toml_key(p) for p in path)}]"] if path else []
    lines += [f"{toml_key(k)} = {toml_value(v)}" for k, v in scalars.items()]
    return "\n".join(lines + [toml_text(v, (*path, k)) for k, v in tables.items()]) + "\n"


def names(change: tuple[str, tuple[str, ...], str, Any]) -> set[str]:
    """Words an error caused by this edit may name: the key and the tables above it."""
    _, path, key, _ = change
    return {key, *path}


@fuzz_settings(300)
@given(base=st.sampled_from(BASES), changes=st.lists(edit(), min_size=1, max_size=4))
def test_any_station_file_parses_or_fails_with_one_line_naming_the_key(base: dict[str, Any],
                                                                      changes: list[tuple]) -> None:
    document = json.loads(json.dumps(base))  # a deep copy (the bases hold no nan)
    for change in changes:
        apply(document, change)
    text = toml_text(document)
    assert tomllib.loads(text) is not None  # the writer makes valid TOML: errors below are the schema's
    try:
        parse_station_config(text, source=SOURCE)
    except ConfigError as error:
        message = str(error)
        assert "\n" not in message and message.startswith(f"{SOURCE}: "), message
        mentioned = set().union(*(names(change) for change in changes))
        assert any(re.search(rf"\b{re.escape(name)}\b", message) for name in mentioned), (message, changes)


def _numeric_kind(hint: Any) -> tuple[str, int | None] | None:
    """("int", "int:CHOICE" or "float"; the fixed array length or None for a scalar), or None for a key with no number."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return _numeric_kind(next(a for a in args if a is not type(None)))
    if origin is typing.Literal:  # an integer choice: its float twin (3.0 == 3) is no integer either
        return (f"int:{args[0]}", None) if all(isinstance(a, int) and not isinstance(a, bool) for a in args) else None
    if origin is tuple:
        inner = _numeric_kind(args[0])
        if inner is None or inner[1] is not None:
            return None
        return inner[0], (1 if args[-1] is Ellipsis else len(args))
    return {int: ("int", None), float: ("float", None)}.get(hint)


NUMERIC = [(path, key, kind) for path, key, hint, _ in FIELDS if (kind := _numeric_kind(hint)) is not None]
SH_TABLES = {"shack_hartmann", "lenslets"}


def _with(path: tuple[str, ...], key: str, value: Any) -> str:
    base = BASES[1] if path[0] in SH_TABLES else BASES[0]
    document = json.loads(json.dumps(base))
    apply(document, ("set", path, key, value))
    return toml_text(document)


def test_every_numeric_key_is_known_to_this_test() -> None:
    assert len(NUMERIC) > 80  # every number of every table, nested aperture included


@pytest.mark.parametrize(("path", "key", "kind"), NUMERIC, ids=[".".join((*p, k)) for p, k, _ in NUMERIC])
def test_a_boolean_nan_or_infinity_is_refused_wherever_a_number_is_meant(path: tuple[str, ...], key: str,
                                                                         kind: tuple[str, int | None]) -> None:
    number_type, length = kind
    bad = [True, False] + ([math.nan, math.inf, -math.inf] if number_type == "float" else [1.5])
    if number_type.startswith("int:"):
        bad.append(float(number_type[len("int:"):]))
    for value in bad:
        text = _with(path, key, value if length is None else [value] * length)
        with pytest.raises(ConfigError) as caught:
            parse_station_config(text, source=SOURCE)
        message = str(caught.value)
        assert re.search(rf"\[{re.escape('.'.join(path))}\] {key}(\[0\])?: expected", message), (value, message)
