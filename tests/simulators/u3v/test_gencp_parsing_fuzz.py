"""Property tests of the simulated camera's GenCP command parser over its whole register space.

Whatever a host writes to the control endpoint (any bytes, or well-formed READMEM / WRITEMEM aimed
anywhere in the bootstrap, SIRM, manifest, feature and XML registers with any data), the device
answers with an acknowledge the host can frame, or with nothing, and never raises.
"""

from __future__ import annotations

import struct

from fuzz import fuzz_settings
from hypothesis import given
from hypothesis import strategies as st

from camera_hooks import AcceptingHooks
from wavestack.simulators.u3v import gencp_device as sim
from wavestack.simulators.u3v.device_description import FEATURES, DeviceIdentity
from wavestack.simulators.u3v.register_map import GenCPStatus
from wavestack.simulators.u3v.registers import (MANIFEST_ADDRESS, SBRM_ADDRESS, SIRM_ADDRESS, XML_ADDRESS,
                                                build_register_map)

IDENTITY = DeviceIdentity("Wavestack", "SimCam", "Sim", "1.0", "fuzz", "0001", 200, 1024, 1024)
STARTS = [0, 0x1C4, 0x1F8, SBRM_ADDRESS, SIRM_ADDRESS, MANIFEST_ADDRESS, XML_ADDRESS,
          *[spec.address for spec in FEATURES]]


def _command(command_id: int, request_id: int, scd: bytes, flags: int = sim.FLAG_REQUEST_ACK) -> bytes:
    return sim.HEADER.pack(sim.CONTROL_PREFIX, flags, command_id, len(scd), request_id) + scd


addresses = st.one_of(st.sampled_from(STARTS).flatmap(lambda a: st.integers(max(a - 8, 0), a + 16)),
                      st.integers(0, 2**64 - 1))
commands = st.one_of(
    st.builds(lambda r, a, n: _command(sim.READMEM_CMD, r, struct.pack("<QHH", a, 0, n)),
              st.integers(0, 0xFFFF), addresses, st.integers(0, 0xFFFF)),
    st.builds(lambda r, a, d: _command(sim.WRITEMEM_CMD, r, struct.pack("<Q", a) + d),
              st.integers(0, 0xFFFF), addresses, st.binary(max_size=24)),
    st.builds(_command, st.integers(0, 0xFFFF), st.integers(0, 0xFFFF), st.binary(max_size=24), st.integers(0, 0xFFFF)),
    st.binary(max_size=40))


@fuzz_settings(300)
@given(packets=st.lists(commands, min_size=1, max_size=6), zipped=st.booleans())
def test_any_command_is_answered_with_a_framed_acknowledge_or_nothing(packets: list[bytes], zipped: bool) -> None:
    device = sim.GenCPDevice(build_register_map(IDENTITY, AcceptingHooks(123), zipped_xml=zipped), max_command_bytes=1024,
                             max_ack_bytes=1024)
    for packet in packets:
        ack = device.execute(packet)
        if ack is None:
            continue
        wire = ack.to_bytes()
        prefix, status, _, scd_length, _ = sim.HEADER.unpack_from(wire)
        assert prefix == sim.CONTROL_PREFIX and scd_length == len(wire) - sim.HEADER.size <= 1024 - 12
        assert status in iter(GenCPStatus)
