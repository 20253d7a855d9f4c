"""Device paths are resolved (``..`` and symlinks) before the allow-list: nothing outside /dev's serial ports passes."""

from __future__ import annotations

import os
import tempfile
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest

from wavestack.drivers.device_path import check_device_path
from wavestack.config.pzt import parse_pzt_config
from wavestack.config.schema import ConfigError


@pytest.fixture
def dev(tmp_path: Path) -> Path:
    """A temporary directory laid out like /dev, with real symlinks, beside a user's home."""
    root = tmp_path / "dev"
    (root / "pts").mkdir(parents=True)
    (root / "serial" / "by-id").mkdir(parents=True)
    home = tmp_path / "home" / "user"
    home.mkdir(parents=True)
    (home / "file").write_text("precious\n")
    for node in ("ttyUSB0", "ttyACM1", "pts/3", "sda", "null"):
        (root / node).write_text("")
    (root / "serial" / "by-id" / "usb-FTDI_piezo").symlink_to("../../ttyUSB0")
    (root / "serial" / "by-id" / "usb-evil").symlink_to("../../../home/user/file")
    (root / "piezo").symlink_to("ttyACM1")  # a udev rule's name
    (root / "disk").symlink_to("sda")
    (root / "outside").symlink_to(home / "file")  # absolute, out of /dev
    (root / "loop").symlink_to("loop")
    return root


@pytest.mark.parametrize("url", [
    "/dev/ttyUSB0", "/dev/ttyACM1", "/dev/pts/3", "/dev/serial/by-id/usb-FTDI_piezo", "/dev/piezo",
    "/dev/ttyS7",  # absent on this machine: resolves to itself, a serial port
    "/dev/serial/by-id/usb-absent",  # absent: a stable name
    "/dev/serial/../ttyUSB0", "COM3",
])
def test_serial_ports_and_links_resolving_to_them_are_allowed(dev: Path, url: str) -> None:
    assert check_device_path(url, dev=str(dev)) is None


@pytest.mark.parametrize(("url", "resolved"), [
    ("/dev/../home/user/file", "home/user/file"),
    ("/dev/ttyUSB0/../../home/user/file", "home/user/file"),
    ("/dev/serial/by-id/usb-evil", "home/user/file"),
    ("/dev/outside", "home/user/file"),
    ("/dev/disk", "/dev/sda"),
    ("/dev/null", "/dev/null"),
    ("/dev/tty", "/dev/tty"),
    ("/dev/loop", "/dev/loop"),
    ("/dev/pts/ptmx", "/dev/pts/ptmx"),
])
def test_paths_resolving_outside_the_serial_ports_are_refused(dev: Path, url: str, resolved: str) -> None:
    reason = check_device_path(url, dev=str(dev))
    assert reason is not None and "resolves to" in reason and resolved in reason


@pytest.mark.parametrize("url", ["/dev/", "/dev/tty USB0", "/etc/passwd", "dev/ttyUSB0", "COM", "/dev//etc/passwd"])
def test_malformed_device_paths_are_refused(url: str) -> None:
    assert check_device_path(url) is not None


def pzt(url: str) -> str:
    return f'[pzt]\nurl = "{url}"\nvolts_per_radian = 2.0\nbias_v = 75.0\n'


def test_a_path_climbing_out_of_dev_is_refused_in_one_line_naming_file_key_and_path() -> None:
    with pytest.raises(ConfigError) as caught:
        parse_pzt_config(tomllib.loads(pzt("/dev/../home/user/file")), source="bench.toml")
    assert str(caught.value) == (
        "bench.toml: [pzt] url: device path '/dev/../home/user/file' is not allowed: resolves to '/home/user/file', "
        "which is not a serial port or terminal under /dev (/dev/tty*, /dev/cu.*, /dev/pts/N, or a /dev/serial/by-id/* "
        "or other /dev symlink resolving to one), or COMn")


@pytest.fixture
def shm_link() -> Iterator[Path]:
    """A real symlink under /dev (in /dev/shm, the one place under /dev a user may write)."""
    shm = Path("/dev/shm")
    if not (shm.is_dir() and os.access(shm, os.W_OK)):
        pytest.skip("no writable /dev/shm on this machine")
    with tempfile.TemporaryDirectory(dir=shm) as folder:
        yield Path(folder) / "link"


def test_a_real_dev_symlink_to_a_users_file_is_refused(shm_link: Path, tmp_path: Path) -> None:
    target = tmp_path / "file"
    target.write_text("precious\n")
    shm_link.symlink_to(target)
    with pytest.raises(ConfigError, match=rf"resolves to '{target}'"):
        parse_pzt_config(tomllib.loads(pzt(str(shm_link))), source="bench.toml")
    assert target.read_text() == "precious\n"


def test_a_real_dev_symlink_to_a_pseudo_terminal_is_allowed(shm_link: Path) -> None:
    controller, terminal = os.openpty()
    try:
        shm_link.symlink_to(os.ttyname(terminal))
        settings, _ = parse_pzt_config(tomllib.loads(pzt(str(shm_link))), source="bench.toml")
        assert settings.url == str(shm_link)  # kept as written: a stable name survives a replug
        assert check_device_path(os.ttyname(terminal)) is None
    finally:
        os.close(controller)
        os.close(terminal)

