"""The floors of ``wavestack/``, checked on the code's own imports (read as text, as ``check_layout.py`` does).

The rules (DESIGN.md, "The floors of wavestack/"):

- the applications ``polish``, ``align`` and ``batch`` stand side by side on the station service and
  the loop kernel: none imports another, and the service and the kernel import none of them;
- nothing outside the simulator starter imports ``wavestack.simulators``: the starter is
  ``wavestack.simulated``; besides it only the station's truth check (``station.sim_truth``, loaded
  for ``sim://`` cameras only), the ``wavestack sim ...`` commands (``cli.sim_*``) and the benchmark
  commands of the simulated station (``bench``) touch a simulator;
- a real bench loads no simulator: the whole command line, the station, the loops and their
  configurations import without ``wavestack.simulators`` (a fresh interpreter proves it);
- values only upward: ``web`` and ``figures`` read values and drive nothing: they import no loop,
  session, runner or station service, and of the applications only their value modules;
- the floors stack: the lower floors (config, the station service, the loop kernel, recording) never
  import a higher one, and no module imports ``cli``.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
APP = ROOT / "wavestack"
SIBLINGS = ("polish", "align", "batch", "calibrate")
#: Modules that may import wavestack.simulators (module notes).
SIMULATOR_USERS = ("wavestack.simulated", "wavestack.station.sim_truth", "wavestack.cli.sim_", "wavestack.bench")
#: The floors from the ground up; a part may import its own floor's service parts and lower floors only.
FLOORS = (
    ("config",),
    ("simulated",),
    ("station", "recording", "loop"),
    ("polish", "align", "batch", "calibrate"),
    ("figures", "web", "bench"),
    ("cli",),
)
#: Modules of the applications that only declare values, which the upper floors may read.
VALUE_MODULES = ("wavestack.polish.run_record", "wavestack.polish.history", "wavestack.align.history")
#: What the upper floors must never import: the things that drive a loop or the station.
DRIVERS_OF_LOOPS = ("wavestack.station.station", "wavestack.station.service", "wavestack.loop.runner")


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    name = ".".join(parts)
    return name[: -len(".__init__")] if name.endswith(".__init__") else name


def _imports(path: Path) -> set[str]:
    """Every module a file imports (anywhere in it: at the top, in a function, under TYPE_CHECKING)."""
    module = _module(path)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            found.update(f"{base}.{alias.name}" for alias in node.names)
            found.add(base)
    return {name for name in found if name.startswith("wavestack")}


def _resolved(names: set[str], modules: set[str]) -> set[str]:
    """Each imported name as the module it lives in (``wavestack.station.Station`` -> ``wavestack.station``)."""
    out = set()
    for name in names:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        if name:
            out.add(name)
    return out


_FILES = sorted(APP.rglob("*.py"))
_MODULES = {_module(path) for path in _FILES} | {"wavestack.drivers", "wavestack.pipeline", "wavestack.simulators"}
EDGES = {_module(path): _resolved(_imports(path), _MODULES) | {t for t in _imports(path) if t.startswith(
    ("wavestack.drivers", "wavestack.pipeline", "wavestack.simulators"))} for path in _FILES}


def _part(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "wavestack" and parts[1] not in (
        "drivers", "pipeline", "simulators") else None


def _floor(part: str) -> int:
    return next(i for i, names in enumerate(FLOORS) if part in names)


def test_every_application_part_has_a_floor() -> None:
    parts = {_part(m) for m in EDGES} - {None}
    assert parts <= {name for floor in FLOORS for name in floor}, parts - {n for f in FLOORS for n in f}


def test_siblings_never_import_each_other() -> None:
    crossing = sorted(f"{m} -> {t}" for m, targets in EDGES.items() for t in targets
                      if _part(m) in SIBLINGS and _part(t) in SIBLINGS and _part(t) != _part(m))
    assert not crossing, crossing


def test_only_the_simulator_starter_imports_simulators() -> None:
    loading = sorted(f"{m} -> {t}" for m, targets in EDGES.items() for t in targets
                     if t.startswith("wavestack.simulators") and not m.startswith(SIMULATOR_USERS))
    assert not loading, loading


def test_floors_import_only_their_own_floor_and_below() -> None:
    upward = sorted(f"{m} -> {t}" for m, targets in EDGES.items() for t in targets
                    if _part(m) and _part(t) and _floor(_part(t)) > _floor(_part(m)))
    assert not upward, upward


def test_web_and_figures_read_values_only() -> None:
    reaching = sorted(f"{m} -> {t}" for m, targets in EDGES.items() for t in targets
                      if _part(m) in ("web", "figures")
                      and ((_part(t) in SIBLINGS and not t.startswith(VALUE_MODULES))
                           or t.startswith(DRIVERS_OF_LOOPS)))
    assert not reaching, reaching


@pytest.mark.parametrize("rule", [test_siblings_never_import_each_other, test_only_the_simulator_starter_imports_simulators,
                                  test_floors_import_only_their_own_floor_and_below,
                                  test_web_and_figures_read_values_only])
def test_each_rule_can_fail(rule, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each rule, given one offending import, fails (so a passing rule is evidence, not an empty loop)."""
    offending = {"wavestack.polish.loop": {"wavestack.align.loop"},
                 "wavestack.station.station": {"wavestack.simulators.optic", "wavestack.polish.loop"},
                 "wavestack.web.feed": {"wavestack.align.loop"}}
    edges = {name: set(targets) for name, targets in EDGES.items()}
    for module, targets in offending.items():
        edges[module] = edges.get(module, set()) | targets
    monkeypatch.setitem(globals(), "EDGES", edges)
    with pytest.raises(AssertionError):
        rule()


def test_a_real_bench_loads_no_simulator(tmp_path: Path) -> None:
    """The whole command line, the station, both loops and a real station's configuration, in a fresh interpreter."""
    code = (
        "import sys\n"
        "import wavestack.cli, wavestack.station, wavestack.polish.loop, wavestack.polish.session\n"
        "import wavestack.align.loop, wavestack.align.session, wavestack.batch, wavestack.web, wavestack.figures\n"
        "from wavestack.config import load_station_config\n"
        "from wavestack.config.align import load_align_config\n"
        f"load_station_config({str(ROOT / 'config' / 'station-hardware.example.toml')!r})\n"
        f"load_align_config({str(ROOT / 'config' / 'tma-alignment-remote.toml')!r})\n"
        "loaded = sorted(m for m in sys.modules if m.startswith('wavestack.simulat'))\n"
        "print(' '.join(loaded))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == [], done.stdout
