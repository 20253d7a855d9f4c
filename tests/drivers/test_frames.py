"""Frame values and device errors."""

from __future__ import annotations

import numpy as np
import pytest

from wavestack.drivers import (DeviceDisconnected, DeviceError, DeviceTimeout, Frame, LimitError, ProtocolError,
                               SlopeFrame)


def test_frame_metadata_is_read_only_and_a_copy() -> None:
    extra = {"pzt_commanded_v": 10.0}
    frame = Frame(1, 2, 3, np.zeros((4, 5), np.uint16), extra)
    extra["pzt_commanded_v"] = 99.0
    assert frame.metadata["pzt_commanded_v"] == 10.0
    with pytest.raises(TypeError):
        frame.metadata["x"] = 1  # type: ignore[index]


def test_frame_pixels_must_be_2d() -> None:
    with pytest.raises(ValueError, match="Frame 7: pixels must be 2-D"):
        Frame(7, 0, 0, np.zeros(5))


def test_slope_frame_arrays_must_agree() -> None:
    SlopeFrame(1, 0, 0, np.zeros(3), np.zeros(3), np.ones(3, bool))
    with pytest.raises(ValueError, match="SlopeFrame 1"):
        SlopeFrame(1, 0, 0, np.zeros(3), np.zeros(4), np.ones(3, bool))


@pytest.mark.parametrize(("error", "bases"), [(DeviceTimeout, TimeoutError), (DeviceDisconnected, ConnectionError),
                                              (LimitError, ValueError), (ProtocolError, DeviceError)])
def test_errors_name_the_device_and_are_catchable_by_their_builtin_kind(error: type, bases: type) -> None:
    raised = error("MDT693B on sim://mdt693b", "expected '[...]', got b'?'")
    assert isinstance(raised, DeviceError) and isinstance(raised, bases)
    assert str(raised) == "MDT693B on sim://mdt693b: expected '[...]', got b'?'"
    assert raised.device == "MDT693B on sim://mdt693b"
