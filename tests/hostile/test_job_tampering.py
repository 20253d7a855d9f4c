"""A job folder on a shared drive: with a job key, only a holder of the key can make a job the machine runs.

The CRC-32 catches accidents; anyone who can write the folder can write a file whose CRC matches.
With ``[plc] job_key_file`` the host signs each job (HMAC-SHA256 in the trailer) and the machine,
holding the same key, refuses any file without the right signature (NOT_SIGNED).
"""

from __future__ import annotations

import secrets
import textwrap
from pathlib import Path

import numpy as np
import pytest

from wavestack.config import ConfigError, load_plc_config
from wavestack.drivers.plc import JobFile, encode_job_file, read_job_key, write_job_file
from wavestack.simulated import machine_settings
from wavestack.simulators.plc import MachineSimSettings, PolishingMachine, StopReason


def _job(job_id: int, dwell_s: float = 1.0) -> JobFile:
    return JobFile(job_id, np.zeros(2), np.zeros(2), np.full(2, dwell_s), np.full(2, 10.0), 0.1,
                   {"kind": "gaussian"}, {"pixels": 1})


def _load(machine: PolishingMachine, job: JobFile, crc: int) -> tuple[str, StopReason]:
    assert machine.load(job.job_id, crc, job.point_count, job.total_dwell_s)
    assert machine.wait_idle(10.0)
    snapshot = machine.snapshot()
    return snapshot.state.name, snapshot.reason


def test_only_jobs_signed_with_the_machines_key_load(tmp_path: Path) -> None:
    key = secrets.token_bytes(32)
    machine = PolishingMachine(MachineSimSettings(tmp_path, job_key=key))
    signed = write_job_file(tmp_path, _job(1), key=key)
    assert _load(machine, _job(1), signed.crc32) == ("LOADED", StopReason.NONE)

    unsigned = write_job_file(tmp_path, _job(2))  # a writer without the key
    assert _load(machine, _job(2), unsigned.crc32)[1] is StopReason.NOT_SIGNED
    wrong = write_job_file(tmp_path, _job(3), key=secrets.token_bytes(32))  # another key
    assert _load(machine, _job(3), wrong.crc32)[1] is StopReason.NOT_SIGNED

    # a signed job whose dwell someone raised, CRC recomputed so the file is intact: the signature fails
    data, _ = encode_job_file(_job(4), key)
    forged, crc = encode_job_file(_job(4, dwell_s=9.0))
    signature = data[data.rindex(b" hmac-sha256 "):]
    (tmp_path / "job-00004.wsjob").write_bytes(forged[:-1] + signature)
    assert _load(machine, _job(4, dwell_s=9.0), crc)[1] is StopReason.NOT_SIGNED
    machine.close()


def test_without_a_key_the_machine_reads_any_intact_job(tmp_path: Path) -> None:
    machine = PolishingMachine(MachineSimSettings(tmp_path))
    receipt = write_job_file(tmp_path, _job(1), key=secrets.token_bytes(32))  # a signed one reads too
    assert _load(machine, _job(1), receipt.crc32) == ("LOADED", StopReason.NONE)
    machine.close()


def test_the_key_file_is_checked_and_found_beside_the_configuration(tmp_path: Path) -> None:
    (tmp_path / "job.key").write_text(secrets.token_hex(32) + "\n")
    config = tmp_path / "plc.toml"
    config.write_text(textwrap.dedent("""
        [plc]
        url = "tcp://127.0.0.1:5020"
        job_folder = "."
        job_key_file = "job.key"
        [plc.simulator.polishing]
    """))
    plc = load_plc_config(config)
    assert machine_settings(plc).job_key == read_job_key(tmp_path / "job.key")
    (tmp_path / "job.key").write_text("not hex\n")
    with pytest.raises(ConfigError, match="job_key_file"):
        machine_settings(load_plc_config(config))
    (tmp_path / "job.key").write_text("abcd\n")
    with pytest.raises(ValueError, match="at least 16"):
        read_job_key(tmp_path / "job.key")
