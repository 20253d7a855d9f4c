#!/usr/bin/env python3
"""Set-up and entry point for a fresh machine: needs only python3.

    python3 ws.py test [PYTEST-ARGS...]   run the test suite (one worker per core; ``-n 0``: one process)
    python3 ws.py COMMAND [ARGS...]       run `wavestack COMMAND ARGS...` (e.g. `fit --example`)

The first call creates ``.venv`` beside this file and installs wavestack into it (editable, with
its test extras). Later calls reuse it; it is reinstalled only when ``pyproject.toml`` changes.
``test`` also needs a few Debian programs: a browser for the web view's test (Chromium,
``/usr/bin/chromium``) and aravis (``arv-tool-0.8``, ``arv-fake-gv-camera-0.8``) for the GigE
Vision tests, installed with ``apt-get`` when missing (as root; Playwright's own browser download
is not used).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
STAMP = VENV / ".wavestack-installed"
CHROMIUM = Path("/usr/bin/chromium")


def _venv_bin(name: str) -> Path:
    return VENV / ("Scripts" if os.name == "nt" else "bin") / name


def _wanted_stamp() -> str:
    digest = hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()
    return f"{digest} {sys.version_info.major}.{sys.version_info.minor}"


def ensure_environment() -> None:
    """Create the virtual environment and install the project if it is missing or stale."""
    if not _venv_bin("python").exists():
        print(f"ws.py: creating {VENV.relative_to(ROOT)} ...", file=sys.stderr, flush=True)
        venv.EnvBuilder(with_pip=True).create(VENV)
    if STAMP.exists() and STAMP.read_text() == _wanted_stamp():
        return
    print("ws.py: installing wavestack and its test dependencies ...", file=sys.stderr, flush=True)
    pip = [str(_venv_bin("python")), "-m", "pip", "--disable-pip-version-check", "-q"]
    subprocess.run([*pip, "install", "-e", f"{ROOT}[test]"], check=True, cwd=ROOT)
    STAMP.write_text(_wanted_stamp())


#: Debian packages the tests need: (what must exist, package, which test needs it)
DEBIAN_TOOLS = ((CHROMIUM, "chromium", "the web view's browser test"),
                (Path("/usr/bin/arv-tool-0.8"), "aravis-tools-cli", "the GigE Vision tests against aravis"),
                (Path("/usr/bin/arv-fake-gv-camera-0.8"), "aravis-tools", "the GigE Vision tests against aravis"))


def ensure_debian_tools() -> None:
    """Install the Debian packages of :data:`DEBIAN_TOOLS` whose programs are missing (one apt-get run).

    Raises
    ------
    OSError
        No apt-get, not root, or a package did not bring its program; the message says what to do.
    """
    missing = [(path, package, why) for path, package, why in DEBIAN_TOOLS if not path.exists()]
    if not missing:
        return
    packages = sorted({package for _, package, _ in missing})
    apt_get = shutil.which("apt-get")
    if apt_get is None or not hasattr(os, "geteuid") or os.geteuid() != 0:
        needs = "; ".join(f"{why} needs {path}" for path, _, why in missing)
        raise OSError(f"{needs}, and they cannot be installed here (needs apt-get as root): install Debian's "
                      f"{' '.join(packages)} (apt-get install {' '.join(packages)})")
    environment = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for command in ([apt_get, "update"], [apt_get, "install", "-y", *packages]):
        print(f"ws.py: {', '.join(str(path) for path, _, _ in missing)} missing: {' '.join(command)}",
              file=sys.stderr, flush=True)
        subprocess.run(command, check=True, env=environment)
    still = [str(path) for path, _, _ in missing if not path.exists()]
    if still:
        raise OSError(f"apt-get installed {' '.join(packages)} but {', '.join(still)} is still missing")


def _parallel(pytest_args: list[str]) -> list[str]:
    """One pytest worker per core (pytest-xdist), a test file's tests on one worker, unless the caller chose.

    Example
    -------
    >>> _parallel([]), _parallel(["-n", "0"])
    (['-n', 'auto', '--dist', 'loadfile'], [])
    """
    chosen = any(a in {"-n", "--numprocesses"} or a.startswith(("-n", "--numprocesses=")) for a in pytest_args)
    return [] if chosen else ["-n", "auto", "--dist", "loadfile"]


def main(argv: list[str]) -> int:
    if not argv or argv[0] in {"-h", "--help"}:
        print(__doc__.strip())
        return 0 if argv else 2
    try:
        ensure_environment()
        if argv[0] == "test":
            ensure_debian_tools()
    except (subprocess.CalledProcessError, OSError) as error:
        print(f"ws.py: set-up failed: {error}", file=sys.stderr)
        return 1
    if argv[0] == "test":
        command = [str(_venv_bin("python")), "-m", "pytest", *_parallel(argv[1:]), *argv[1:]]
    else:
        command = [str(_venv_bin("wavestack")), *argv]
    return subprocess.run(command, cwd=ROOT).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
