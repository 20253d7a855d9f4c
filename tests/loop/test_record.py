"""The kernel's campaign record: a CRC-32 per record, an exclusive create, and a reader that keeps what is intact."""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from wavestack.loop import MAP_KIND, CampaignWriter, read_campaign
from wavestack.pipeline import InputError

FORMAT = "wavestack-test-campaign"


def _write(path: Path, maps: int = 4, close: bool = True) -> CampaignWriter:
    writer = CampaignWriter(path, FORMAT, "[loop]\nkey = 1\n", {"shape": [8, 8], "gain": 0.5}, software_version="t")
    writer.event("measuring", "start")
    for i in range(maps):
        writer.append_map(np.full((8, 8), float(i)), units="nm", exposure_unix_s=100.0 + i,
                          mask=np.ones((8, 8), bool) if i == 0 else None, fields={"rms_nm": float(i)})
    writer.append("run", {"run": 1, "predicted": float("nan")}, {"job_file": b"\x00\x01job"})
    if close:
        writer.close({"final_phase": "target-met"})
    return writer


def test_every_record_reads_back_as_written(tmp_path: Path) -> None:
    path = tmp_path / "c.h5"
    _write(path)
    log = read_campaign(path, FORMAT)
    assert log.damage == () and log.closed_cleanly and log.header == {"shape": [8, 8], "gain": 0.5}
    assert log.config_text == "[loop]\nkey = 1\n"
    assert [e.kind for e in log.records] == ["event", *[MAP_KIND] * 4, "run", "end"]
    maps = log.of_kind(MAP_KIND)
    np.testing.assert_array_equal(maps[2].arrays["map"], np.full((8, 8), 2.0, np.float32))
    assert maps[0].arrays["aperture_mask"].dtype == bool and "aperture_mask" not in maps[1].arrays
    assert maps[3].fields == {"rms_nm": 3.0, "units": "nm", "exposure_unix_s": 103.0}
    run = log.of_kind("run")[0]
    assert run.fields["predicted"] is None and bytes(run.arrays["job_file"]) == b"\x00\x01job"  # NaN -> null


def test_a_changed_value_or_field_is_named_and_the_rest_reads(tmp_path: Path) -> None:
    path = tmp_path / "c.h5"
    _write(path)
    with h5py.File(path, "r+") as f:
        stored = f["records/000002/map"]
        stored[0, 0] = 99.0
        f["records/000004"].attrs["fields"] = np.bytes_(b'{"rms_nm": 0.0, "units": "nm", "exposure_unix_s": 103.0}')
    log = read_campaign(path, FORMAT)
    assert [d.split(":")[0] for d in log.damage] == ["record 000002", "record 000004"]
    assert all("CRC-32 mismatch" in d for d in log.damage)
    assert [e.index for e in log.of_kind(MAP_KIND)] == [1, 3] and log.of_kind("end")


def test_a_killed_writer_leaves_every_flushed_record_intact(tmp_path: Path) -> None:
    path = tmp_path / "c.h5"
    writer = _write(path, maps=6, close=False)
    shutil.copy(path, tmp_path / "killed.h5")  # flushed after every record, never closed: as a killed writer leaves it
    writer.close({"final_phase": "faulted"})
    log = read_campaign(tmp_path / "killed.h5", FORMAT)
    assert not log.closed_cleanly and log.damage == ()
    assert len(log.of_kind(MAP_KIND)) == 6 and not log.of_kind("end")


def test_a_record_the_writer_did_not_finish_is_incomplete(tmp_path: Path) -> None:
    path = tmp_path / "c.h5"
    _write(path)
    with h5py.File(path, "r+") as f:
        del f["records/000003"].attrs["crc32"]  # the CRC is written last
    log = read_campaign(path, FORMAT)
    assert log.damage == ("record 000003: incomplete (the writer stopped while writing it)",)


@pytest.mark.parametrize("fraction", [0.05, 0.3, 0.9])
def test_a_cut_copy_is_an_input_error_or_a_named_damage_never_a_hang(tmp_path: Path, fraction: float) -> None:
    path = tmp_path / "c.h5"
    _write(path)
    data = path.read_bytes()
    cut = tmp_path / "cut.h5"
    cut.write_bytes(data[: int(len(data) * fraction)])
    try:
        log = read_campaign(cut, FORMAT)
    except InputError as error:
        assert str(cut) in str(error)
    else:
        assert log.damage and "truncated" in log.damage[0]


def test_never_overwrites_and_refuses_other_formats(tmp_path: Path) -> None:
    path = tmp_path / "c.h5"
    _write(path)
    with pytest.raises(FileExistsError):
        CampaignWriter(path, FORMAT, "", {})
    with pytest.raises(InputError, match="not a wavestack-other record"):
        read_campaign(path, "wavestack-other")
    assert read_campaign(path).format_name == FORMAT  # None: any loop's record


def test_a_closed_writer_and_a_field_that_is_not_json_are_refused(tmp_path: Path) -> None:
    writer = _write(tmp_path / "c.h5", close=False)
    with pytest.raises(TypeError):
        writer.append("run", {"value": object()})
    writer.close({})
    writer.close({})  # idempotent
    with pytest.raises(ValueError, match="closed"):
        writer.event("late", "")
