"""Configuration files: TOML tables checked against dataclass schemas.

A schema is a frozen dataclass whose fields are declared with :func:`setting`, which adds bounds,
choices and a URL allow-list to the type hint. :func:`parse_section` turns one TOML table into an
instance or raises :class:`ConfigError` naming the file, the key and what was expected. Unknown
keys are errors too: a misspelt ``vlimit`` must not silently fall back to a default.

Supported field types: ``bool``, ``int``, ``float`` (an integer literal is accepted), ``str``,
``Literal[...]``, ``X | None``, ``tuple[X, ...]`` and ``tuple[X, Y, ...]`` (TOML arrays), and nested
schema dataclasses (TOML sub-tables).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import stat
import tomllib
import types
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

from wavestack.drivers.device_path import check_device_path, is_device_path
from wavestack.pipeline import InputError

T = TypeVar("T")

#: URL kinds a device field may allow. ``device`` is a local device path (``/dev/...``, ``COMn``).
URL_KINDS = ("sim", "socket", "tcp", "usb", "usbtcp", "gige", "device")
#: Integers are TOML's: signed 64-bit.
_INT64 = (-(2 ** 63), 2 ** 63 - 1)
_SCHEME = re.compile(r"^([a-z][a-z0-9+.-]*)://")


class ConfigError(InputError):
    """A configuration that does not validate; the message names file, key and expectation."""


def setting(
    default: Any = dataclasses.MISSING,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    choices: Sequence[Any] | None = None,
    url_kinds: Sequence[str] | None = None,
    doc: str = "",
) -> Any:
    """Declare a schema field with its checks.

    Parameters
    ----------
    default
        Value when the key is absent; omit to make the key required. Mutable defaults are not
        allowed (use tuples).
    minimum, maximum
        Inclusive numeric bounds (applied to every element of a tuple).
    choices
        Allowed values.
    url_kinds
        For device URLs: the allowed kinds from :data:`URL_KINDS`.
    doc
        One line for error messages and the commented example files.
    """
    if url_kinds is not None:
        unknown = set(url_kinds) - set(URL_KINDS)
        if unknown:
            raise ValueError(f"unknown URL kinds {sorted(unknown)}; known: {URL_KINDS}")
    metadata = {"minimum": minimum, "maximum": maximum, "choices": None if choices is None else tuple(choices),
                "url_kinds": None if url_kinds is None else tuple(url_kinds), "doc": doc}
    return dataclasses.field(default=default, metadata=metadata)


def url_kind(url: str) -> str | None:
    """The kind of a device URL (``sim``, ``socket``, ``tcp``, ``usb``, ``usbtcp``, ``gige``, ``device``) or None.

    ``device`` only says the URL is written as a local path; whether that path is allowed is
    :func:`~wavestack.config.device_path.check_device_path`'s decision (resolved, symlinks
    followed), which :func:`parse_section` applies to every device field.
    """
    if is_device_path(url):
        return "device"
    match = _SCHEME.match(url)
    return match.group(1) if match else None


#: Largest configuration file read, bytes (the shipped ones are a few kilobytes).
MAX_CONFIG_BYTES = 1 << 20


def read_config_text(path: str | Path) -> str:
    """The text of a configuration file: a regular file of at most :data:`MAX_CONFIG_BYTES`, UTF-8.

    Opened without blocking (a FIFO is refused, not waited on) and read at most one byte past the
    bound (``/dev/zero`` is refused, not read forever).

    Raises
    ------
    ConfigError
        Missing, not a regular file, too large, unreadable, or not UTF-8; the message names it.
    """
    path = Path(path)
    try:
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such configuration file") from None
    except OSError as error:
        raise ConfigError(f"{path}: cannot read ({error.strerror})") from None
    try:
        with open(descriptor, "rb", closefd=True) as handle:
            if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):
                raise ConfigError(f"{path}: not a regular file (a folder, FIFO or device); expected a TOML file")
            data = handle.read(MAX_CONFIG_BYTES + 1)
    except OSError as error:
        raise ConfigError(f"{path}: cannot read ({error.strerror})") from None
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(f"{path}: larger than {MAX_CONFIG_BYTES} bytes; expected a TOML configuration")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ConfigError(f"{path}: not UTF-8 text ({error.reason} at byte {error.start})") from None


def parse_toml(text: str, source: str) -> dict[str, Any]:
    """A TOML document; malformed or too deeply nested TOML raises :class:`ConfigError` naming ``source``."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(f"{source}: not valid TOML ({error})") from None
    except RecursionError:
        raise ConfigError(f"{source}: not valid TOML (arrays or tables nested too deeply)") from None


def load_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file (:func:`read_config_text`, :func:`parse_toml`); errors are :class:`ConfigError`."""
    return parse_toml(read_config_text(path), str(path))


def device_tables(document: Mapping[str, Any], name: str, *, what: str,
                  source: str) -> tuple[Mapping[str, Any], Mapping[str, Any] | None]:
    """Split a device's table ``[name]`` from its simulator's ``[name.simulator]``.

    Returns
    -------
    (table without ``simulator``, the simulator table or None when absent)

    Raises
    ------
    ConfigError
        ``[name]`` is missing or not a table; ``what`` says what it should hold.
    """
    table = document.get(name)
    if not isinstance(table, Mapping):
        raise ConfigError(f"{source}: missing table [{name}] ({what})")
    return {k: v for k, v in table.items() if k != "simulator"}, table.get("simulator")


def parse_section(schema: type[T], table: Any, *, source: str, section: str) -> T:
    """Check one TOML table against a schema dataclass and build it.

    Parameters
    ----------
    schema
        A dataclass whose fields were declared with :func:`setting` (or plain defaults).
    table
        The TOML table (a mapping).
    source
        The file the table came from, for messages.
    section
        Dotted name of the table in the file (``"pzt"``, ``"camera.optic"``).

    Raises
    ------
    ConfigError
        Unknown or missing keys, wrong types, values out of range or not among the choices, URLs of
        a kind not allowed.
    """
    where = f"{source}: [{section}]" if section else f"{source}:"
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where} expected a table, got {_describe(table)}")
    fields = {f.name: f for f in dataclasses.fields(schema)}  # type: ignore[arg-type]
    unknown = sorted(set(table) - set(fields))
    if unknown:
        raise ConfigError(f"{where} unknown key {unknown[0]!r}; expected one of: {', '.join(sorted(fields))}")
    hints = typing.get_type_hints(schema)
    values: dict[str, Any] = {}
    for name, spec in fields.items():
        if name not in table:
            if spec.default is dataclasses.MISSING and spec.default_factory is dataclasses.MISSING:
                raise ConfigError(f"{where} missing required key {name!r}" + _doc_suffix(spec))
            continue
        values[name] = _check(table[name], hints[name], spec, f"{where} {name}", source,
                              f"{section}.{name}" if section else name)
    try:
        return schema(**values)
    except (ValueError, TypeError) as error:  # the schema's own __post_init__ checks name the field
        raise ConfigError(f"{where} {error}") from None


def _doc_suffix(spec: dataclasses.Field[Any]) -> str:
    doc = spec.metadata.get("doc", "") if spec.metadata else ""
    return f" ({doc})" if doc else ""


def _describe(value: Any) -> str:
    kind = {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
            list: "an array", dict: "a table"}.get(type(value), type(value).__name__)
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 128:
        return f"{kind} of {value.bit_length()} bits"  # repr() of a huge integer may itself fail
    shown = repr(value)
    return f"{kind} {shown if len(shown) <= 40 else shown[:37] + '...'}"


def _check(value: Any, hint: Any, spec: dataclasses.Field[Any], where: str, source: str, section: str) -> Any:
    checked = _convert(value, hint, where, source, section)
    meta = spec.metadata or {}
    items = checked if isinstance(checked, tuple) else (checked,)
    for item in items:
        if meta.get("minimum") is not None and item is not None and item < meta["minimum"]:
            raise ConfigError(f"{where}: expected >= {meta['minimum']}, got {item!r}" + _doc_suffix(spec))
        if meta.get("maximum") is not None and item is not None and item > meta["maximum"]:
            raise ConfigError(f"{where}: expected <= {meta['maximum']}, got {item!r}" + _doc_suffix(spec))
    if meta.get("choices") is not None and checked not in meta["choices"]:
        allowed = ", ".join(repr(c) for c in meta["choices"])
        raise ConfigError(f"{where}: expected one of {allowed}, got {checked!r}")
    if meta.get("url_kinds") is not None and checked is not None:
        kind = url_kind(checked)
        if kind not in meta["url_kinds"]:
            raise ConfigError(f"{where}: URL {checked!r} is not allowed; expected "
                              + " or ".join(_url_kind_text(k) for k in meta["url_kinds"]))
        reason = check_device_path(checked) if kind == "device" else None
        if reason is not None:
            raise ConfigError(f"{where}: device path {checked!r} is not allowed: {reason}")
    return checked


def _url_kind_text(kind: str) -> str:
    return "a device path (/dev/..., COMn)" if kind == "device" else f"{kind}://..."


def _convert(value: Any, hint: Any, where: str, source: str, section: str) -> Any:
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        options = [a for a in args if a is not type(None)]
        if len(options) != 1:
            raise TypeError(f"schema field {where}: only 'X | None' unions are supported")
        return _convert(value, options[0], where, source, section)
    if origin is typing.Literal:
        # the type must match too: TOML true is a Python bool, an int, and 1.0 == 1
        if not any(type(value) is type(a) and value == a for a in args):
            shown = repr(value) if isinstance(value, str) else _describe(value)
            raise ConfigError(f"{where}: expected one of {', '.join(repr(a) for a in args)}, got {shown}")
        return value
    if origin is tuple:
        if not isinstance(value, list):
            raise ConfigError(f"{where}: expected an array, got {_describe(value)}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f"{where}[{i}]", source, section) for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{where}: expected an array of {len(args)} values, got {len(value)}")
        return tuple(_convert(v, a, f"{where}[{i}]", source, section) for i, (v, a) in enumerate(zip(value, args)))
    if dataclasses.is_dataclass(hint):
        return parse_section(hint, value, source=source, section=section)
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {_describe(value)}")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {_describe(value)}")
        if not _INT64[0] <= value <= _INT64[1]:
            raise ConfigError(f"{where}: expected a 64-bit integer, got {_describe(value)}")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: expected a number, got {_describe(value)}")
        try:
            number = float(value)
        except OverflowError:  # an integer beyond any float
            number = math.inf
        if not math.isfinite(number):
            raise ConfigError(f"{where}: expected a finite number, got {_describe(value)}")
        return number
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {_describe(value)}")
        return value
    raise TypeError(f"schema field {where}: unsupported type {hint!r}")
