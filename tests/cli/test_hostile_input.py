"""Every command, given hostile but legitimate input, ends in exit status 2 and one line naming the input.

The table is the probe of issue 13 kept as a test: each case is a command line and the files it
reads (written by the case into a fresh folder); the command must refuse it with exactly one line
on standard error that names the offending input (a file, an option, a path to write), print
nothing on standard output, and never show a traceback. The expected fragment is what the line
must contain: the name of the input.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest

import hostile_files as hf
from wavestack.cli import build_parser, error_line, main, one_line, run_command
from wavestack.cli.outputs import json_text

ROOT = Path(__file__).resolve().parents[2]
HARDWARE = ROOT / "config" / "station-hardware.example.toml"


@dataclass(frozen=True)
class Case:
    """A command line (``{d}`` is the case's folder), the files it needs, and what the line must name."""

    argv: str
    names: str
    build: Callable[[Path], object] = lambda folder: None


def _map(folder: Path) -> None:
    hf.npy(folder / "map.npy", np.random.default_rng(0).normal(size=(48, 48)))


def _damaged_png(path: Path, cut: bool = False) -> None:
    """A fringe PNG with its compressed data damaged (libpng complains on fd 2) or cut in half."""
    frame = (120 + 100 * np.cos(0.3 * np.indices((64, 64))[1])).astype(np.uint8)
    data = bytearray(cv2.imencode(".png", frame)[1].tobytes())
    if cut:
        del data[len(data) // 2:]
    else:
        data[60] ^= 0xFF
    path.write_bytes(bytes(data))


def _frames(folder: Path) -> None:
    hf.fringes(folder)


def _both(*builders: Callable[[Path], object]) -> Callable[[Path], None]:
    def build(folder: Path) -> None:
        for builder in builders:
            builder(folder)
    return build


FIT = "fit {d}/map.npy"
FRAMES = "analyze {d}/frame0.png {d}/frame1.png {d}/frame2.png {d}/frame3.png"
CASES = {
    # sizes: unbounded allocations
    "modes-100000": Case(FIT + " --modes 100000", "--modes", _map),
    "mesh-vertices-1e8": Case(FIT + " --method csf-qcm --mesh-vertices 100000000", "--mesh-vertices", _map),
    "png-declaring-200000-square-rgb": Case("analyze {d}/big.png --wavelength-nm 633", "big.png",
                                            lambda d: hf.png_declaring(d / "big.png", 200_000, 200_000)),
    "datx-6kb-declaring-40000-square": Case("fit {d}/big.datx", "big.datx",
                                            lambda d: hf.datx_declaring(d / "big.datx", 40_000, 40_000)),
    "datx-declaring-unwritten-4000-square": Case("fit {d}/sparse.datx", "sparse.datx",
                                                 lambda d: hf.datx_declaring(d / "sparse.datx", 4000, 4000)),
    "h5-declaring-40000-square": Case("fit {d}/big.h5", "big.h5",
                                      lambda d: hf.fourd_declaring(d / "big.h5", 40_000, 40_000)),
    "npy-declaring-1e6-square": Case("fit {d}/big.npy", "big.npy",
                                     lambda d: hf.npy_declaring(d / "big.npy", (1_000_000, 1_000_000))),
    "npy-truncated": Case("fit {d}/cut.npy", "cut.npy", lambda d: hf.npy_declaring(d / "cut.npy", (40, 40))),
    # malformed .datx / .h5 / .dat / images / .npy
    "datx-string-surface": Case("fit {d}/s.datx", "s.datx", lambda d: hf.datx_string_surface(d / "s.datx")),
    "datx-link-loop": Case("fit {d}/loop.datx", "loop.datx", lambda d: hf.datx_link_loop(d / "loop.datx")),
    "datx-dangling-link": Case("fit {d}/dangle.datx", "dangle.datx",
                               lambda d: hf.datx_dangling_link(d / "dangle.datx")),
    "datx-no-wavelength-analyze": Case("analyze {d}/nowl.datx", "nowl.datx",
                                       lambda d: hf.datx(d / "nowl.datx", wavelength_m=None)),
    "datx-wavelength-1e-30": Case("analyze {d}/wl.datx", "wl.datx",
                                  lambda d: hf.datx(d / "wl.datx", wavelength_m=1e-30)),
    "datx-unknown-unit": Case("fit {d}/unit.datx", "unit.datx", lambda d: hf.datx(d / "unit.datx", unit="parsecs")),
    "datx-values-1e300": Case("fit {d}/huge.datx --json", "huge.datx",
                              lambda d: hf.datx(d / "huge.datx", np.full((32, 32), 1e300))),
    "datx-garbage-bytes": Case("fit {d}/junk.datx", "junk.datx",
                               lambda d: (d / "junk.datx").write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(300))),
    "h5-other-layout": Case("fit {d}/other.h5", "other.h5",
                            lambda d: hf.datx(d / "other.h5")),
    "h5-wavelength-words": Case("fit {d}/w.h5", "w.h5", lambda d: hf.fourd_h5(d / "w.h5", wavelength="red")),
    "h5-string-map": Case("fit {d}/s.h5", "s.h5", lambda d: hf.fourd_h5(d / "s.h5", np.array([b"x", b"y"]))),
    "dat-wavelength-1e-30": Case("analyze {d}/wl.dat", "wl.dat",
                                 lambda d: hf.metropro_dat(d / "wl.dat", wavelength_m=1e-30)),
    "dat-wavelength-nan": Case("fit {d}/nan.dat", "nan.dat",
                               lambda d: hf.metropro_dat(d / "nan.dat", wavelength_m=float("nan"))),
    "dat-random-bytes": Case("fit {d}/r.dat", "r.dat",
                             lambda d: (d / "r.dat").write_bytes(np.random.default_rng(2).bytes(2000))),
    "dat-empty": Case("fit {d}/e.dat", "e.dat", lambda d: (d / "e.dat").write_bytes(b"")),
    "png-empty": Case("analyze {d}/e.png --wavelength-nm 633", "e.png", lambda d: (d / "e.png").write_bytes(b"")),
    "png-corrupt-idat": Case("analyze {d}/bad.png --wavelength-nm 633", "bad.png", lambda d: _damaged_png(d / "bad.png")),
    "png-truncated": Case("analyze {d}/cut.png --wavelength-nm 633", "cut.png",
                          lambda d: _damaged_png(d / "cut.png", cut=True)),
    "png-not-an-image": Case("analyze {d}/t.png --wavelength-nm 633", "t.png",
                             lambda d: (d / "t.png").write_text("hello")),
    "npy-pickled-object": Case("fit {d}/o.npy", "o.npy",
                               lambda d: np.save(d / "o.npy", np.array([{"a": 1}], dtype=object))),
    "npy-3d": Case("fit {d}/c.npy", "c.npy", lambda d: hf.npy(d / "c.npy", np.zeros((2, 8, 8)))),
    "npy-all-nan": Case("fit {d}/n.npy", "n.npy", lambda d: hf.npy(d / "n.npy", np.full((8, 8), np.nan))),
    "npy-values-1e300": Case("fit {d}/h.npy --json", "h.npy", lambda d: hf.npy(d / "h.npy", np.full((32, 32), 1e300))),
    "npy-complex": Case("fit {d}/z.npy", "z.npy", lambda d: hf.npy(d / "z.npy", np.zeros((8, 8), complex))),
    "mask-wrong-shape": Case(FIT + " --mask {d}/m.npy", "m.npy",
                             _both(_map, lambda d: hf.npy(d / "m.npy", np.ones((5, 5), bool)))),
    "mask-empty": Case(FIT + " --mask {d}/m.npy", "m.npy",
                       _both(_map, lambda d: hf.npy(d / "m.npy", np.zeros((48, 48), bool)))),
    "missing-file": Case("fit {d}/absent.npy", "absent.npy"),
    "unsupported-kind": Case("fit {d}/x.mat", "x.mat", lambda d: (d / "x.mat").write_bytes(b"MATLAB")),
    # outputs: checked before anything is computed
    "save-fit-missing-folder": Case(FIT + " --save-fit {d}/no/such/folder/x.npy", "--save-fit", _map),
    "save-fit-onto-directory": Case(FIT + " --save-fit {d}", "--save-fit", _map),
    "save-fit-onto-dev-null": Case(FIT + " --save-fit /dev/null", "--save-fit", _map),
    "save-map-missing-folder": Case(FRAMES + " --wavelength-nm 633 --save-map {d}/no/x.npy", "--save-map", _frames),
    "save-map-onto-directory": Case(FRAMES + " --wavelength-nm 633 --save-map {d}", "--save-map", _frames),
    "save-map-onto-dev-null": Case(FRAMES + " --wavelength-nm 633 --save-map /dev/null", "--save-map", _frames),
    "record-missing-folder": Case("run --frames 1 --record {d}/no/x.h5", "--record"),
    "record-onto-directory": Case("run --frames 1 --record {d}", "--record"),
    "record-onto-dev-null": Case("run --frames 1 --record /dev/null", "--record"),
    # physically meaningless values
    "wavelength-0": Case(FRAMES + " --wavelength-nm 0", "--wavelength-nm", _frames),
    "wavelength-negative": Case(FRAMES + " --wavelength-nm -5", "--wavelength-nm", _frames),
    "wavelength-nan": Case(FRAMES + " --wavelength-nm nan", "--wavelength-nm", _frames),
    "wavelength-inf": Case(FRAMES + " --wavelength-nm inf", "--wavelength-nm", _frames),
    "wavelength-words": Case(FRAMES + " --wavelength-nm red", "--wavelength-nm", _frames),
    "identical-frames": Case("analyze {d}/frame0.png {d}/frame1.png {d}/frame2.png {d}/frame3.png "
                             "--wavelength-nm 633", "frame0.png", lambda d: hf.fringes(d, identical=True)),
    "identical-frames-with-mask": Case(
        "analyze {d}/frame0.png {d}/frame1.png {d}/frame2.png {d}/frame3.png --wavelength-nm 633 --mask {d}/m.npy",
        "frame0.png", _both(lambda d: hf.fringes(d, identical=True),
                            lambda d: hf.npy(d / "m.npy", np.ones((128, 128), bool)))),
    "carrier-sign-2": Case("analyze {d}/frame0.png --wavelength-nm 633 --carrier-sign 2", "--carrier-sign", _frames),
    "carrier-sign-0": Case("analyze {d}/frame0.png --wavelength-nm 633 --carrier-sign 0", "--carrier-sign", _frames),
    "carrier-sign-true": Case("analyze {d}/frame0.png --wavelength-nm 633 --carrier-sign true", "--carrier-sign",
                              _frames),
    "steps-nan": Case(FRAMES + " --wavelength-nm 633 --steps 0,nan,180,270", "--steps", _frames),
    "steps-count": Case(FRAMES + " --wavelength-nm 633 --steps 0,90,180", "--steps", _frames),
    "roc-negative": Case(FRAMES + " --wavelength-nm 633 --roc-mm -1 --diameter-mm 100", "--roc-mm", _frames),
    "diameter-inf": Case(FRAMES + " --wavelength-nm 633 --roc-mm 1000 --diameter-mm inf", "--diameter-mm", _frames),
    "null-conic-nan": Case(FRAMES + " --wavelength-nm 633 --null-conic nan", "--null-conic", _frames),
    "pupil-nan": Case(FIT + " --pupil 1,2,nan", "--pupil", _map),
    "pupil-zero-radius": Case(FIT + " --pupil 1,2,0", "--pupil", _map),
    "pupil-words": Case(FIT + " --pupil a,b,c", "--pupil", _map),
    "modes-words": Case(FIT + " --modes many", "--modes", _map),
    "modes-negative": Case(FIT + " --modes -3", "--modes", _map),
    "mesh-vertices-zero": Case(FIT + " --mesh-vertices 0", "--mesh-vertices", _map),
    "ordering-garbage": Case(FIT + " --ordering zz", "--ordering", _map),
    "method-garbage": Case(FIT + " --method zz", "--method", _map),
    "sh-focal-length-inf": Case("analyze {d}/frame0.png --wavelength-nm 633 --lenslet-pitch-um 150 "
                                "--pixel-um 5 --focal-length-mm inf", "--focal-length-mm", _frames),
    "run-frames-words": Case("run --frames many", "--frames"),
    "run-duration-nan": Case("run --duration nan", "--duration"),
    "run-config-missing": Case("run --frames 1 --config {d}/absent.toml", "absent.toml"),
    "bench-results-zero": Case("bench station --results 0", "--results"),
    "bench-paper-with-config": Case("bench paper --config {d}/x.toml", "--config"),
    "bench-station-with-aperture": Case("bench station --aperture circle", "--aperture"),
    "fit-example-with-mask": Case("fit --example --mask {d}/m.npy", "--mask"),
}


@pytest.fixture(autouse=True)
def _nothing_written_beside_dev_null():
    """numpy.save('/dev/null') wrote /dev/null.npy; a case that does it again fails (and is cleaned up)."""
    existed = Path("/dev/null.npy").exists()
    yield
    if not existed and Path("/dev/null.npy").exists():
        Path("/dev/null.npy").unlink()
        pytest.fail("/dev/null.npy was written")


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        status = main(argv)
    except SystemExit as stop:  # argparse refuses an option's value before the handler runs
        status = int(stop.code or 0)
    captured = capsys.readouterr()
    return status, captured.out, captured.err


@pytest.mark.parametrize("name", list(CASES))
def test_hostile_input_is_one_line_naming_it(name: str, tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    # capfd: what C libraries (libpng, HDF5) print on file descriptor 2 counts as a line too
    case = CASES[name]
    case.build(tmp_path)
    argv = case.argv.format(d=tmp_path).split()
    status, out, err = _run(argv, capfd)
    lines = err.strip().splitlines()
    assert "Traceback" not in err, err
    assert status == 2, (status, err)
    assert len(lines) == 1, err
    assert case.names in lines[0], lines[0]
    assert out == ""


def test_record_into_a_missing_folder_fails_before_any_device_is_opened(tmp_path: Path, capsys) -> None:
    # The hardware example asks for a real USB camera, which this machine does not have: had the
    # devices been opened first, the camera's failure would be the error (exit status 3).
    status, _, err = _run(["run", "--config", str(HARDWARE), "--frames", "1",
                           "--record", str(tmp_path / "missing" / "x.h5")], capsys)
    assert status == 2 and "--record" in err and "device error" not in err, err


def _namespace(handler: Callable[..., int], *, verbose: bool = False) -> argparse.Namespace:
    return argparse.Namespace(command="fit", verbose=verbose, wavefront="x.npy", subject=lambda args: "x.npy",
                              handler=handler)


def _raise(error: BaseException) -> Callable[..., int]:
    def handler(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
        raise error
    return handler


@pytest.mark.parametrize("error, status, fragment", [
    (ValueError("no fringes"), 2, "wavestack fit: error: x.npy: no fringes"),
    (ValueError("x.npy: no fringes"), 2, "wavestack fit: error: x.npy: no fringes"),
    (MemoryError(), 2, "x.npy: not enough memory"),
    (FileNotFoundError(2, "No such file or directory", "out.npy"), 2, "out.npy: No such file"),
    (KeyError("bug"), 1, "internal error (a bug, please report it): KeyError"),
])
def test_every_failure_is_one_line_with_its_exit_status(error, status, fragment, capsys) -> None:
    assert run_command(_namespace(_raise(error)), build_parser()) == status
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and fragment in err and "Traceback" not in err, err
    if status == 1:
        assert "run with -v for the traceback" in err


def test_an_internal_error_logs_its_traceback_with_verbose(capsys, caplog) -> None:
    assert run_command(_namespace(_raise(KeyError("bug")), verbose=True), build_parser()) == 1
    assert "run with -v" not in capsys.readouterr().err
    assert "Traceback" in caplog.text and "KeyError: 'bug'" in caplog.text


def test_a_message_on_several_lines_becomes_one() -> None:
    assert one_line("a\n  b\tc") == "a b c"
    args = argparse.Namespace(files=["x.png", "y.png"], subject=lambda a: "x.png (and 1 more)")
    assert error_line(args, ValueError("y.png: too small")) == "y.png: too small"  # names an input: kept


def test_saved_map_goes_to_exactly_the_given_name(tmp_path: Path, capsys) -> None:
    _map(tmp_path)
    target = tmp_path / "fitted.map"  # not .npy: numpy.save on a name would write fitted.map.npy
    assert main(["fit", str(tmp_path / "map.npy"), "--modes", "6", "--save-fit", str(target)]) == 0
    assert target.exists() and not (tmp_path / "fitted.map.npy").exists()
    assert np.load(target).shape == (48, 48)


def test_colour_frame_is_reduced_without_a_float64_copy_of_the_frame(tmp_path: Path) -> None:
    import tracemalloc

    from wavestack.pipeline import read_frame

    image = np.random.default_rng(3).integers(0, 255, size=(2000, 1000, 3), dtype=np.uint8)
    path = tmp_path / "colour.png"
    cv2.imwrite(str(path), image)
    tracemalloc.start()
    try:
        frame = read_frame(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert frame.shape == (2000, 1000)
    # the decoded image is 6 MB and the frame 2 MB; a float64 copy of the colour image alone is
    # 48 MB (the old path), the row blocks of 2^18 pixels are 6 MB each
    assert peak < 32e6, peak


def _strict(text: str) -> object:
    def refuse(constant: str) -> None:
        raise AssertionError(f"bare {constant} in JSON")
    return json.loads(text, parse_constant=refuse)


def test_json_has_no_bare_nan_or_infinity(tmp_path: Path, capsys) -> None:
    assert _strict(json_text({"a": float("nan"), "b": [1.0, float("inf")], "c": (-float("inf"),)})) == {
        "a": None, "b": [1.0, None], "c": [None]}
    _map(tmp_path)
    assert main(["fit", str(tmp_path / "map.npy"), "--modes", "6", "--json"]) == 0
    report = _strict(capsys.readouterr().out)
    assert isinstance(report, dict) and len(report["coefficients"]) == 6
