"""Configuration schemas: every bad input is refused with the file, the key and what was expected."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import pytest

from wavestack.config.schema import ConfigError, load_toml, parse_section, setting, url_kind


@dataclass(frozen=True)
class Inner:
    gain: float = setting(1.0, minimum=0.0)


@dataclass(frozen=True)
class Device:
    url: str = setting(url_kinds=("sim", "socket", "device"), doc="where the device is")
    limit_v: float = setting(150.0, minimum=0.0, maximum=150.0)
    axes: tuple[str, ...] = setting(("x",), choices=None)
    echo: bool = True
    prompt: Literal[">", "*"] = ">"
    size: tuple[int, int] = (640, 480)
    inner: Inner = Inner()
    name: str | None = None


def parse(table: dict) -> Device:
    return parse_section(Device, table, source="bench.toml", section="pzt")


def test_a_valid_table_builds_the_schema_with_defaults() -> None:
    device = parse({"url": "/dev/ttyUSB0", "limit_v": 100, "size": [1024, 1024], "inner": {"gain": 2}})
    assert device == Device(url="/dev/ttyUSB0", limit_v=100.0, size=(1024, 1024), inner=Inner(2.0))
    assert isinstance(device.limit_v, float)


@pytest.mark.parametrize(("table", "expected"), [
    ({"url": "sim://x", "limt_v": 1}, r"bench.toml: \[pzt\] unknown key 'limt_v'; expected one of: .*limit_v"),
    ({}, r"bench.toml: \[pzt\] missing required key 'url' \(where the device is\)"),
    ({"url": "sim://x", "limit_v": 151}, r"\[pzt\] limit_v: expected <= 150"),
    ({"url": "sim://x", "limit_v": -1}, r"\[pzt\] limit_v: expected >= 0"),
    ({"url": "sim://x", "limit_v": "high"}, r"limit_v: expected a number, got a string 'high'"),
    ({"url": "sim://x", "limit_v": True}, r"limit_v: expected a number, got a boolean"),
    ({"url": "sim://x", "echo": 1}, r"echo: expected true or false"),
    ({"url": "sim://x", "prompt": "#"}, r"prompt: expected one of '>', '\*', got '#'"),
    ({"url": "sim://x", "size": [1, 2, 3]}, r"size: expected an array of 2 values, got 3"),
    ({"url": "sim://x", "size": [1, 2.5]}, r"size\[1\]: expected an integer"),
    ({"url": "sim://x", "axes": "x"}, r"axes: expected an array"),
    ({"url": "sim://x", "inner": {"gain": -2}}, r"\[pzt.inner\] gain: expected >= 0"),
    ({"url": "sim://x", "inner": {"gian": 1}}, r"\[pzt.inner\] unknown key 'gian'"),
    ({"url": "http://example.com"}, r"url: URL 'http://example.com' is not allowed; expected sim://"),
    ({"url": "ttyUSB0"}, r"url: URL 'ttyUSB0' is not allowed"),
])
def test_bad_values_name_the_file_the_key_and_the_expectation(table: dict, expected: str) -> None:
    with pytest.raises(ConfigError, match=expected):
        parse(table)


def test_a_non_table_section_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"\[pzt\] expected a table, got an integer"):
        parse_section(Device, 3, source="bench.toml", section="pzt")


@pytest.mark.parametrize(("url", "kind"), [("/dev/ttyUSB0", "device"), ("COM3", "device"), ("sim://mdt693b", "sim"),
                                           ("socket://localhost:7777", "socket"), ("usb://", "usb"), ("x", None)])
def test_url_kinds(url: str, kind: str | None) -> None:
    assert url_kind(url) == kind


def test_load_toml_names_the_file_when_missing_or_malformed(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no such configuration file"):
        load_toml(tmp_path / "absent.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[pzt\nurl = 1\n")
    with pytest.raises(ConfigError, match=r"bad.toml: not valid TOML"):
        load_toml(bad)


def test_an_unknown_url_kind_in_a_schema_is_a_programming_error() -> None:
    with pytest.raises(ValueError, match="unknown URL kinds"):
        setting(url_kinds=("http",))
