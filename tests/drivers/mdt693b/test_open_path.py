"""The piezo driver checks a local device path again just before it opens the port (issue 13)."""

from __future__ import annotations

import pytest

from wavestack.drivers.mdt693b import MDT693B


def test_the_piezo_driver_refuses_a_path_that_leaves_dev_before_opening_it(tmp_path) -> None:
    # checked again at open time: code that builds a driver without a configuration gets it too
    target = tmp_path / "precious.txt"
    target.write_text("keep me")
    piezo = MDT693B(f"/dev/..{target}")
    with pytest.raises(ValueError, match="refusing to open .*resolves to"):
        piezo.open(timeout_s=0.5)
    assert target.read_text() == "keep me"
