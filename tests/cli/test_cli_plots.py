"""``--plot`` (analyze, fit) and ``--plots`` (bench paper, replay) as a user runs them: the PNGs written,
their size, the maps not blank, and bad output paths refused in one line before any work."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import matplotlib.image
import numpy as np
import pytest

from wavestack.cli import main
from wavestack.figures import DPI, FIT_FIGURE_INCHES

SMALL = Path(__file__).resolve().parents[1] / "configs" / "station-small.toml"
CLI = "import sys; from wavestack.cli import main; sys.exit(main())"
FIT_PIXELS = (round(FIT_FIGURE_INCHES[1] * DPI), round(FIT_FIGURE_INCHES[0] * DPI))


def _disk_map(tmp_path: Path, size: int = 40) -> Path:
    rows, cols = np.indices((size, size))
    x, y = (cols - size / 2) / (size / 2), (size / 2 - rows) / (size / 2)
    inside = np.hypot(x, y) < 0.95
    path = tmp_path / "map.npy"
    np.save(path, np.where(inside, 0.3 * (2 * (x**2 + y**2) - 1) + 0.1 * x * y, np.nan))
    return path


def _coloured_fraction(path: Path) -> float:
    """Share of pixels that are neither white nor grey: the false colour of the maps and the bars."""
    rgb = matplotlib.image.imread(path)[..., :3]
    return float(np.mean(np.ptp(rgb, axis=-1) > 0.15))


def test_fit_plot_writes_the_figure(capsys, tmp_path) -> None:
    out = tmp_path / "fit.png"
    assert main(["fit", str(_disk_map(tmp_path)), "--method", "circle", "--modes", "15", "--plot", str(out)]) == 0
    assert "defocus" in capsys.readouterr().out
    image = matplotlib.image.imread(out)
    assert image.shape[:2] == FIT_PIXELS
    assert _coloured_fraction(out) > 0.05  # three maps and the bars; a blank figure has none


def _fringes(tmp_path: Path, size: int = 64) -> list[str]:
    rows, cols = np.indices((size, size))
    x, y = (cols - size / 2) / (size / 2.4), (size / 2 - rows) / (size / 2.4)
    inside = np.hypot(x, y) < 1
    phase = 2 * np.pi * (1.5 * (x**2 + y**2) + 0.4 * x)
    files = []
    for k in range(4):
        frame = np.where(inside, 128 + 100 * np.cos(phase + k * np.pi / 2), 0)
        files.append(str(tmp_path / f"frame{k}.png"))
        cv2.imwrite(files[-1], frame.astype(np.uint8))
    return files


def test_analyze_plot_writes_the_figure(capsys, tmp_path) -> None:
    out = tmp_path / "analyze.png"
    assert main(["analyze", *_fringes(tmp_path), "--wavelength-nm", "633", "--modes", "15", "--json",
                 "--plot", str(out)]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["modes"] == 15 and matplotlib.image.imread(out).shape[:2] == FIT_PIXELS
    assert _coloured_fraction(out) > 0.05


@pytest.mark.parametrize("command", ["fit", "analyze"])
@pytest.mark.parametrize("bad, fragment", [("missing-folder/out.png", "does not exist"), (".", "directory")])
def test_a_bad_plot_path_is_one_line_before_any_work(capsys, tmp_path, command, bad, fragment) -> None:
    target = str(tmp_path / bad)
    # the input does not exist either: the output path is checked first, so its error is the one shown
    argv = [command, str(tmp_path / "absent.npy"), "--plot", target]
    assert main(argv + (["--wavelength-nm", "633"] if command == "analyze" else [])) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1
    assert "--plot" in captured.err and fragment in captured.err and target.rstrip("/.") in captured.err


def test_plots_options_where_they_do_not_apply(capsys, tmp_path) -> None:
    assert main(["analyze", str(tmp_path / "spots.png"), "--reference", str(tmp_path / "ref.png"),
                 "--plot", str(tmp_path / "out.png")]) == 2
    assert "--plot draws interferograms and measured maps, not a Shack-Hartmann" in capsys.readouterr().err
    assert main(["bench", "station", "--plots", str(tmp_path)]) == 2
    assert "--plots applies to 'bench paper' only" in capsys.readouterr().err
    assert main(["bench", "paper", "--size", "8"]) == 2
    assert "--size 8: expected at least 32" in capsys.readouterr().err
    afile = tmp_path / "file"
    afile.write_text("x")
    assert main(["bench", "paper", "--plots", str(afile)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--plots {afile}: not a folder" in err
    assert main(["replay", str(tmp_path / "absent.h5"), "--plots", str(tmp_path / "no" / "such")]) == 2
    err = capsys.readouterr().err  # the folder is checked before the recording is opened
    assert err.count("\n") == 1 and "does not exist or is not writable" in err


@pytest.mark.slow
def test_bench_paper_plots_draws_the_papers_figures(capsys, tmp_path) -> None:
    folder = tmp_path / "figures"  # made by the command
    assert main(["bench", "paper", "--aperture", "rounded-rectangle", "--size", "48", "--json",
                 "--plots", str(folder)]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert len(rows) == 6 and "views" not in rows[0]
    names = sorted(p.name for p in folder.iterdir())
    assert names == sorted([f"{s}-rounded-rectangle.png" for s in ("meshes", "beltrami", "gram", "errors")]
                           + ["area-scale-ecdf.png"])
    fractions = {n: _coloured_fraction(folder / n) for n in names}
    assert fractions.pop("area-scale-ecdf.png") > 0.002, fractions  # curves only
    assert all(f > 0.02 for f in fractions.values()), fractions  # maps, matrices, bars


@pytest.mark.slow
def test_replay_plots_draws_the_recording(tmp_path) -> None:
    record = tmp_path / "run.h5"
    done = subprocess.run([sys.executable, "-c", CLI, "run", "--config", str(SMALL), "--frames", "4", "--json",
                           "--record", str(record)], capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stderr
    folder = tmp_path / "plots"
    done = subprocess.run([sys.executable, "-c", CLI, "replay", str(record), "--plots", str(folder)],
                          capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in folder.iterdir()) == ["coefficients.png", "last-map.png", "latency.png"]
    assert _coloured_fraction(folder / "last-map.png") > 0.05  # the last result's map, not a placeholder
    assert matplotlib.image.imread(folder / "latency.png").shape[:2] == (5 * DPI, 8 * DPI)
