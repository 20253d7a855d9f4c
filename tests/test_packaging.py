"""The four folders install as one `wavestack` namespace, in a wheel as well as editable."""

from __future__ import annotations

import os
import site
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = {"wavestack": "wavestack", "drivers": "wavestack.drivers",
           "pipeline": "wavestack.pipeline", "simulators": "wavestack.simulators"}


def _declared() -> tuple[list[str], dict[str, str]]:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    return config["packages"], config["package-dir"]


def test_every_package_folder_is_declared_in_pyproject() -> None:
    packages, package_dir = _declared()
    found = set()
    for folder, dotted in FOLDERS.items():
        assert package_dir[dotted] == folder
        for init in (ROOT / folder).rglob("__init__.py"):
            relative = init.parent.relative_to(ROOT / folder).parts
            found.add(".".join((dotted, *relative)))
    assert found == set(packages), "pyproject's [tool.setuptools] packages must list every package folder"


@pytest.mark.slow
def test_wheel_installs_all_four_packages(tmp_path) -> None:
    built = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"), str(ROOT)],
        capture_output=True, text=True, timeout=600, check=False,
    )
    assert built.returncode == 0, built.stderr
    (wheel,) = (tmp_path / "dist").glob("wavestack-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for dotted in FOLDERS.values():
        assert dotted.replace(".", "/") + "/__init__.py" in names
    target = tmp_path / "installed"
    installed = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target), str(wheel)],
        capture_output=True, text=True, timeout=600, check=False,
    )
    assert installed.returncode == 0, installed.stderr
    # Run without `site` so the editable install's .pth finder is not loaded: wavestack can only
    # come from the wheel; numpy and friends come from this environment's site-packages.
    code = (
        "import sys; sys.path[:0] = [sys.argv[1]]; sys.path.extend(sys.argv[2:]);"
        "import wavestack, wavestack.drivers, wavestack.pipeline, wavestack.simulators;"
        "from wavestack.pipeline import Aperture, build_fitter; import numpy as np;"
        "mods = [wavestack, wavestack.drivers, wavestack.pipeline, wavestack.simulators];"
        "assert all(m.__file__.startswith(sys.argv[1]) for m in mods), [m.__file__ for m in mods];"
        "f = build_fitter(np.ones((9, 9), bool), modes=3); print(f.n_modes)"
    )
    ran = subprocess.run(
        [sys.executable, "-S", "-c", code, str(target), *site.getsitepackages()],
        capture_output=True, text=True, timeout=120, check=False, cwd=tmp_path,
        env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"},
    )
    assert ran.returncode == 0, ran.stderr
    assert ran.stdout.strip() == "3"
