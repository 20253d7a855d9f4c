"""The PLC's result display block as a third party (the machine's HMI) reads it: a plain pymodbus
client, FC3, and pymodbus's own float32 converter, never the driver's codec."""

from __future__ import annotations

from pymodbus.client import ModbusTcpClient


def read_panel(client: ModbusTcpClient, address: int, word_order: str = "little") -> dict[str, object]:
    """The 8 registers at ``address``, decoded by the documented layout (CDAB = pymodbus's little word order)."""
    reply = client.read_holding_registers(address, count=8, device_id=1)
    assert not reply.isError(), reply
    words = reply.registers

    def real(pair: list[int]) -> float:
        return float(ModbusTcpClient.convert_from_registers(pair, ModbusTcpClient.DATATYPE.FLOAT32,
                                                            word_order=word_order))  # type: ignore[arg-type]
    return {"counter": words[0], "flags": words[1], "valid": bool(words[1] & 1), "figures": bool(words[1] & 2),
            "rms_nm": real(words[2:4]), "pvr_nm": real(words[4:6]), "spec": words[6], "limiting": words[7]}
