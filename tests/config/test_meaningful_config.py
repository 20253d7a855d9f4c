"""Configurations that validate by type but can never work are refused, each with one line naming file, key and value.

Every case edits one or two keys of the shipped simulated station (``wavestack/config/default.toml``)
and expects one :class:`ConfigError` line that names the file, the table and key, and the value.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from wavestack.config import DEFAULT_CONFIG, load_plc_config, load_pzt_config, load_station_config
from wavestack.config.schema import ConfigError
from wavestack.config.station import parse_station_config

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_TEXT = DEFAULT_CONFIG.read_text(encoding="utf-8")
SOURCE = "bench.toml"


def with_keys(text: str, table: str, **values: str) -> str:
    """``text`` with ``key = value`` (TOML literals) set in ``[table]``, replacing the key's line if present."""
    lines = text.splitlines()
    start = lines.index(next(line for line in lines if re.match(rf"^\[{re.escape(table)}\]", line))) + 1
    end = next((i for i in range(start, len(lines)) if lines[i].startswith("[")), len(lines))
    for key, value in values.items():
        found = [i for i in range(start, end) if re.match(rf"^{key}\s*=", lines[i])]
        if found:
            lines[found[0]] = f"{key} = {value}"
        else:
            lines.insert(start, f"{key} = {value}")
            end += 1
    return "\n".join(lines) + "\n"


def refused(text: str) -> str:
    with pytest.raises(ConfigError) as caught:
        parse_station_config(text, source=SOURCE)
    message = str(caught.value)
    assert "\n" not in message, message
    assert message.startswith(f"{SOURCE}: "), message
    return message


HARIHARAN = '"hariharan"'
LSQ = '"lsq"'

# (table, {key: TOML value}, the message must match this)
REFUSED = [
    # phase steps the algorithm cannot use
    ("processing", {"psi_algorithm": LSQ, "steps_deg": "[]"},
     r"\[processing\] steps_deg = \[\]: expected 3 to 32 steps, got 0 \(psi_algorithm = 'lsq'\)"),
    ("processing", {"psi_algorithm": LSQ, "steps_deg": "[0.0]"}, r"steps_deg = \[0\]: expected 3 to 32 steps, got 1"),
    ("processing", {"psi_algorithm": LSQ, "steps_deg": "[90.0, 90.0, 90.0, 90.0, 90.0]"},
     r"steps_deg = \[90, 90, 90, 90, 90\]: expected at least 3 steps distinct modulo 360 degrees"),
    ("processing", {"psi_algorithm": '"pca"', "steps_deg": "[0.0, 360.0, 720.0]"},
     r"steps_deg = \[0, 360, 720\]: expected at least 3 steps distinct modulo 360"),
    ("processing", {"psi_algorithm": LSQ, "steps_deg": "[0.0, 10.0, 20.0]"},
     r"steps_deg = \[0, 10, 20\]: expected steps spread over the cycle \(least-squares condition number <= 20"),
    ("processing", {"psi_algorithm": LSQ, "steps_deg": "[" + ", ".join(["0.0", "120.0", "240.0"] * 11) + "]"},
     r"steps_deg = \[0, 120, 240, 0, 120, 240, 0, 120, \.\.\.\]: expected 3 to 32 steps, got 33"),
    ("processing", {"psi_algorithm": HARIHARAN, "steps_deg": "[0.0, 90.0, 180.0, 270.0]"},
     r"steps_deg = \[0, 90, 180, 270\]: expected 5 steps 90 degrees apart.*psi_algorithm = 'hariharan'"),
    ("processing", {"psi_algorithm": '"four"', "steps_deg": "[0.0, 90.0, 180.0, 180.0]"},
     r"expected 4 steps 90 degrees apart, e.g. \[0.0, 90.0, 180.0, 270.0\] \(psi_algorithm = 'four'\)"),
    # booleans and floats where an integer choice is meant
    ("processing", {"carrier_sign": "true"}, r"\[processing\] carrier_sign: expected one of 1, -1, got a boolean True"),
    ("processing", {"carrier_sign": "1.0"}, r"carrier_sign: expected one of 1, -1, got a number 1.0"),
    ("processing", {"modes": "true"}, r"\[processing\] modes: expected an integer, got a boolean True"),
    ("station", {"wavelength_nm": "true"}, r"\[station\] wavelength_nm: expected a number, got a boolean True"),
    # physically meaningless numbers
    ("station", {"wavelength_nm": "0"}, r"\[station\] wavelength_nm: expected >= 100.0, got 0.0"),
    ("station", {"wavelength_nm": "-5"}, r"\[station\] wavelength_nm: expected >= 100.0, got -5.0"),
    ("station", {"wavelength_nm": "nan"}, r"\[station\] wavelength_nm: expected a finite number, got a number nan"),
    ("station", {"wavelength_nm": "inf"}, r"\[station\] wavelength_nm: expected a finite number, got a number inf"),
    ("station", {"wavelength_nm": "-inf"}, r"wavelength_nm: expected a finite number, got a number -inf"),
    ("optic", {"noise_rms": "nan"}, r"\[optic\] noise_rms: expected a finite number, got a number nan"),
    ("optic", {"noise_rms": "-0.1"}, r"\[optic\] noise_rms: expected a number >= 0, got -0.1"),  # the simulator's own check
    ("optic", {"zernike_waves": "[inf]"}, r"\[optic\] zernike_waves\[0\]: expected a finite number"),
    ("station", {"wavelength_nm": "1" + "0" * 400}, r"wavelength_nm: expected a finite number, got an integer of 1329"),
    ("optic", {"seed": "9223372036854775808"}, r"\[optic\] seed: expected a 64-bit integer"),
    # phase steps beyond the piezo's limits
    ("pzt", {"bias_v": "100.0"},
     r"\[processing\] steps_deg\[2\] = 180 deg needs 131.4 V on the piezo \(\[pzt\] bias_v 100 \+ volts_per_radian "
     r"10 x 3.142 rad\); expected every step inside \[pzt\] software_min_v..software_max_v = \[0, 120\] V"),
    ("pzt", {"volts_per_radian": "-10.0"}, r"steps_deg\[2\] = 180 deg needs -11.42 V.*\[pzt\] bias_v 20"),
    ("pzt", {"software_min_v": "25.0"}, r"steps_deg\[0\] = 0 deg needs 20 V.*= \[25, 120\] V"),
    ("pzt.simulator", {"vlimit_v": "75.0"},
     r"steps_deg\[4\] = 360 deg needs 82.83 V.*inside \[pzt\] software_min_v..\[pzt.simulator\] vlimit_v = \[0, 75\] V"),
    # a set that can never arrive in time
    ("pzt", {"settle_s": "0.5"},
     r"\[station\] frame_timeout_s = 2 s: expected more than 5 steps x \[pzt\] settle_s 0.5 s = 2.5 s"),
    ("pzt", {"settle_s": "0.3"},
     r"\[station\] max_result_age_s = 1 s: expected more than \(5 - 1\) steps x \[pzt\] settle_s 0.3 s = 1.2 s"),
    # a simulated bench whose fringes never move
    ("bench", {"axis": '"y"'}, r"\[bench\] axis = 'y': expected \[pzt\] phase_axis 'x'"),
    ("bench", {"radians_per_volt": "0.0"}, r"\[bench\] radians_per_volt = 0: expected a nonzero coupling"),
    # pixel format and bit depth
    ("camera", {"pixel_format": '"Mono8"'},
     r"\[camera\] pixel_format = 'Mono8': expected the simulated camera's \[camera.simulator\] pixel_format 'Mono12'"),
    ("optic", {"bit_depth": "16"},
     r"\[optic\] bit_depth = 16: expected 12, the bit depth of \[camera.simulator\] pixel_format 'Mono12'"),
    # outputs
    ("outputs", {"max_step_nm": "300.0"}, r"\[outputs\] max_step_nm = 300: expected <= max_removal_nm \(200\)"),
    ("outputs", {"first_term": "40"}, r"\[outputs\] first_term = 40: expected <= \[processing\] modes \(36\)"),
    ("outputs", {"max_removal_nm": "600.0"},
     r"\[outputs\] max_removal_nm = 600: expected <= the simulated machine's \[plc.simulator.polishing\] max_removal_nm"),
    ("plc", {"command_block": "[100, 20]", "output_block": "[200, 20]"}, r"initial_surface_nm: expected 9 terms"),
    # a self-check constant that cannot tell the word order, or cannot be sent
    ("plc", {"self_check_value": "0.0"},
     r"\[plc\] self_check_value = 0.0: expected a nonzero constant whose four byte orders differ"),
    ("plc", {"self_check_value": "1e300"}, r"\[plc\] register map: self_check_value must lie within the float32 range.*got 1e\+300"),
    # the PLC's watchdog outlives one retried command
    ("plc", {"io_timeout_s": "1.0"},
     r"\[plc\] io_timeout_s \(1\) x \(1 \+ command_retries 2\) = 3 s: expected less than watchdog_timeout_s \(2\)"),
    # after a short PLC outage the host's back-off alone must not outlast the watchdog
    ("plc", {"reconnect_max_s": "2.0"}, r"\[plc\] reconnect_max_s = 2: expected at most a quarter of watchdog_timeout_s"),
]


@pytest.mark.parametrize(("table", "values", "expected"), REFUSED,
                         ids=[f"{t}-{'-'.join(v)}-{i}" for i, (t, v, _) in enumerate(REFUSED)])
def test_a_configuration_that_can_never_work_is_refused_in_one_line(table: str, values: dict[str, str],
                                                                    expected: str) -> None:
    assert re.search(expected, refused(with_keys(DEFAULT_TEXT, table, **values)))


def test_first_term_beyond_the_command_block_is_refused() -> None:
    text = with_keys(DEFAULT_TEXT, "plc", command_block="[100, 8]", output_block="[200, 8]")
    text = with_keys(text, "plc.simulator.polishing", initial_surface_nm="[0.0, 0.0, 0.0]")
    text = with_keys(text, "outputs", first_term="5")
    assert re.search(r"\[outputs\] first_term = 5: expected <= the 3 terms of \[plc\] command_block \[100, 8\]",
                     refused(text))


def test_each_fixed_step_algorithm_takes_its_own_steps_from_any_first_step() -> None:
    four = with_keys(DEFAULT_TEXT, "processing", psi_algorithm='"four"', steps_deg="[10.0, 100.0, 190.0, 280.0]")
    assert parse_station_config(four, source=SOURCE).processing.frames_per_set == 4
    for algorithm in ("lsq", "aia", "pca"):
        three = with_keys(DEFAULT_TEXT, "processing", psi_algorithm=f'"{algorithm}"', steps_deg="[0.0, 120.0, 240.0]")
        assert parse_station_config(three, source=SOURCE).processing.frames_per_set == 3


def test_a_carrier_station_ignores_the_phase_steps() -> None:
    text = with_keys(DEFAULT_TEXT, "processing", method='"carrier"', steps_deg="[]")
    assert parse_station_config(text, source=SOURCE).processing.frames_per_set == 1


STATION_FILES = [DEFAULT_CONFIG, ROOT / "config" / "shack-hartmann.toml", ROOT / "config" / "shack-hartmann-hex.toml",
                 ROOT / "config" / "station-hardware.example.toml",
                 ROOT / "config" / "tma-alignment-remote-station.toml",
                 *sorted((ROOT / "tests" / "configs").glob("*.toml"))]


@pytest.mark.parametrize("path", STATION_FILES, ids=lambda p: p.name)
def test_every_shipped_station_file_still_validates(path: Path) -> None:
    assert load_station_config(path).source == str(path)


def test_every_shipped_device_file_still_validates() -> None:
    for name in ("plc-sim.toml", "plc-example.toml"):
        assert load_plc_config(ROOT / "config" / name).link.n_terms == 15
    for name in ("pzt-sim.toml", "pzt-mdt693b.example.toml"):
        assert load_pzt_config(ROOT / "config" / name)[0].volts_per_radian == 2.0
    station_files = {p.name for p in STATION_FILES}
    assert {p.name for p in (ROOT / "config").glob("*.toml")} - station_files == {
        "plc-sim.toml", "plc-example.toml", "pzt-sim.toml", "pzt-mdt693b.example.toml",
        "polishing-zygo.toml", "hexapod-sim.toml", "tma-alignment-remote.toml"}, "a new example needs a test"
    # polishing: tests/config/test_polishing_settings.py; hexapod: test_hexapod_settings.py;
    # the real alignment bench: tests/align/test_real_bench.py


def test_a_free_running_camera_slower_than_the_timeouts_is_refused() -> None:
    text = with_keys(DEFAULT_TEXT, "processing", method='"carrier"')
    text = with_keys(text, "camera.simulator", frame_rate_hz="0.1")
    assert re.search(r"\[camera\] timeout_s = 2 s: expected more than the frame period 10 s of \[camera.simulator\] "
                     r"frame_rate_hz 0.1", refused(text))
    # a phase-stepping camera is triggered, not free running
    assert parse_station_config(with_keys(DEFAULT_TEXT, "camera.simulator", frame_rate_hz="0.1"), source=SOURCE)


def test_rings_beyond_the_memory_bound_are_refused() -> None:
    text = with_keys(DEFAULT_TEXT, "camera.simulator", width="8192", height="8192")
    text = with_keys(text, "camera", ring_capacity="64")
    assert re.search(r"\[camera\] ring_capacity 64 \+ \[station\] set_ring_capacity 2 x 5 frames of \[camera.simulator\] "
                     r"8192 x 8192 Mono12 hold 9.25 GiB; expected at most 2 GiB", refused(text))


def test_a_lenslet_grid_larger_than_the_simulated_frame_is_refused() -> None:
    text = with_keys((ROOT / "config" / "shack-hartmann.toml").read_text(encoding="utf-8"), "camera.simulator",
                     width="640")
    assert re.search(r"\[shack_hartmann\] pitch_px, offset_px, grid_shape: 800 of 1600 lenslet windows of the square "
                     r"lattice .* leave the frame of shape \(1024, 640\); expected all inside \(\[camera.simulator\] "
                     r"width 640, height 1024\)", refused(text))
    # the hexagonal station's array likewise; with lattice = "auto" the simulated array's kind is checked
    hexagonal = with_keys((ROOT / "config" / "shack-hartmann-hex.toml").read_text(encoding="utf-8"),
                          "camera.simulator", width="640")
    assert re.search(r"lenslet windows of the hexagonal lattice .* leave the frame of shape \(1024, 640\)",
                     refused(hexagonal))


def test_an_auto_lattice_needs_the_simulated_arrays_kind() -> None:
    text = (ROOT / "config" / "shack-hartmann-hex.toml").read_text(encoding="utf-8")
    assert load_station_config(ROOT / "config" / "shack-hartmann-hex.toml").lenslets.lattice == "hexagonal"
    assert re.search(r"\[lenslets\] lattice: the simulated array's kind .* needed when \[shack_hartmann\] "
                     r"lattice = 'auto'", refused(text.replace('lattice = "hexagonal"', "")))
