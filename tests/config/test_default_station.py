"""The one default station file: inside the package, loadable from the editable install and from a wheel."""

from __future__ import annotations

import os
import site
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from wavestack.config import DEFAULT_CONFIG, load_station_config

ROOT = Path(__file__).resolve().parents[2]


def test_the_default_is_the_packaged_file_and_loads() -> None:
    assert DEFAULT_CONFIG.name == "default.toml" and DEFAULT_CONFIG.parent.name == "config"
    assert DEFAULT_CONFIG.parent.parent.name == "wavestack"  # in the package, not the repository's config/
    config = load_station_config()
    assert config.source == str(DEFAULT_CONFIG) and config.camera.simulated


@pytest.mark.slow
def test_a_wheel_ships_the_default_station(tmp_path: Path) -> None:
    built = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"), str(ROOT)],
        capture_output=True, text=True, timeout=600, check=False,
    )
    assert built.returncode == 0, built.stderr
    (wheel,) = (tmp_path / "dist").glob("wavestack-*.whl")
    assert "wavestack/config/default.toml" in zipfile.ZipFile(wheel).namelist()
    target = tmp_path / "installed"
    installed = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target), str(wheel)],
        capture_output=True, text=True, timeout=600, check=False,
    )
    assert installed.returncode == 0, installed.stderr
    # without `site`, so wavestack can only come from the wheel (as in tests/test_packaging.py)
    code = ("import sys; sys.path[:0] = [sys.argv[1]]; sys.path.extend(sys.argv[2:]);"
            "from wavestack.config import DEFAULT_CONFIG, load_station_config;"
            "assert DEFAULT_CONFIG.is_relative_to(sys.argv[1]), DEFAULT_CONFIG;"
            "print(load_station_config().station.kind)")
    ran = subprocess.run(
        [sys.executable, "-S", "-c", code, str(target), *site.getsitepackages()],
        capture_output=True, text=True, timeout=120, check=False, cwd=tmp_path,
        env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"},
    )
    assert ran.returncode == 0, ran.stderr
    assert ran.stdout.strip() == "interferometer"
