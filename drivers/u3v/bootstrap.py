"""USB3 Vision bootstrap registers (ABRM, SBRM, SIRM) and the manifest table, without I/O.

Decoders take the bytes read from the device at a register map's base address and return frozen
dataclasses; all fields are little-endian. Offsets follow the wavestack protocol sheet
(``u3v_spec.md``), which follows GenCP 1.x (ABRM) and USB3 Vision 1.0/1.1 (SBRM, SIRM).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from wavestack.drivers.errors import ProtocolError

# ABRM (technology-agnostic bootstrap register map) at address 0.
ABRM_ADDRESS = 0x0000
ABRM_SIZE = 0x0204  # up to and including the timestamp increment
ABRM_MAX_RESPONSE_TIME = 0x01CC
ABRM_MANIFEST_TABLE_ADDRESS = 0x01D0
ABRM_SBRM_ADDRESS = 0x01D8
ABRM_TIMESTAMP = 0x01F0
ABRM_TIMESTAMP_LATCH = 0x01F8
_ABRM_STRING_SIZE = 64

# SBRM (technology-specific bootstrap register map).
SBRM_SIZE = 0x44

# SIRM (streaming interface register map): offsets from the SIRM base address.
SIRM_SIZE = 0x30
SIRM_SI_INFO = 0x00
SIRM_SI_CONTROL = 0x04
SIRM_REQUIRED_PAYLOAD_SIZE = 0x08
SIRM_MAX_LEADER_SIZE = 0x18
SIRM_PAYLOAD_TRANSFER_SIZE = 0x1C
SIRM_PAYLOAD_TRANSFER_COUNT = 0x20
SIRM_FINAL_TRANSFER1_SIZE = 0x24
SIRM_FINAL_TRANSFER2_SIZE = 0x28
SIRM_MAX_TRAILER_SIZE = 0x2C
SI_CONTROL_STREAM_ENABLE = 0x1
#: Largest SIRM values the host accepts (the transfer sizes it derives must fit the SIRM's u32 fields,
#: and the read buffers they size must stay reasonable): 1 MiB alignment, leader and trailer; a
#: payload that 2**32 - 1 transfers of 1 MiB carry.
SIRM_MAX_ALIGNMENT = 1 << 20
SIRM_MAX_LEADER_OR_TRAILER = 1 << 20
SIRM_MAX_PAYLOAD = 0xFFFF_FFFF << 20

# Manifest table: u64 entry count, then 64-byte entries.
MANIFEST_COUNT_SIZE = 8
MANIFEST_ENTRY_SIZE = 64
MANIFEST_FORMAT_XML = 0
MANIFEST_FORMAT_ZIP = 1

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_SBRM = struct.Struct("<IQQIIIQIQIQI")
_SIRM = struct.Struct("<IIQIIIIIIII")
_MANIFEST_ENTRY = struct.Struct("<IIQQ20s20s")


def _require(data: bytes, size: int, what: str, device: str) -> bytes:
    data = bytes(data)
    if len(data) < size:
        raise ProtocolError(device, f"expected >= {size} bytes of {what}, got {len(data)}")
    return data


def _ascii(field: bytes) -> str:
    """A NUL-padded ASCII string field; undecodable bytes are replaced, never raised on."""
    return field.split(b"\x00", 1)[0].decode("ascii", errors="replace").strip()


@dataclass(frozen=True)
class Abrm:
    """The GenCP technology-agnostic bootstrap register map (the fields wavestack uses).

    Attributes
    ----------
    gencp_version
        (major, minor).
    manufacturer, model, family, device_version, manufacturer_info, serial_number, user_name
        Identification strings.
    capability
        Device capability bits (u64).
    max_response_time_ms
        Longest time the device takes to acknowledge a command, ms.
    manifest_table_address, sbrm_address
        Register addresses (u64).
    device_configuration
        Device configuration bits (u64).
    timestamp_increment_ns
        Nanoseconds per timestamp tick.
    """

    gencp_version: tuple[int, int]
    manufacturer: str
    model: str
    family: str
    device_version: str
    manufacturer_info: str
    serial_number: str
    user_name: str
    capability: int
    max_response_time_ms: int
    manifest_table_address: int
    sbrm_address: int
    device_configuration: int
    timestamp_increment_ns: int


def decode_abrm(data: bytes, device: str) -> Abrm:
    """Decode the ABRM from the ``ABRM_SIZE`` bytes read at address 0.

    Raises
    ------
    ProtocolError
        Fewer than ``ABRM_SIZE`` bytes.
    """
    data = _require(data, ABRM_SIZE, "ABRM", device)
    minor, major = struct.unpack_from("<HH", data, 0x0000)
    strings = [_ascii(data[offset:offset + _ABRM_STRING_SIZE]) for offset in range(0x0004, 0x01C4, 0x40)]
    return Abrm(
        gencp_version=(major, minor),
        manufacturer=strings[0],
        model=strings[1],
        family=strings[2],
        device_version=strings[3],
        manufacturer_info=strings[4],
        serial_number=strings[5],
        user_name=strings[6],
        capability=_U64.unpack_from(data, 0x01C4)[0],
        max_response_time_ms=_U32.unpack_from(data, ABRM_MAX_RESPONSE_TIME)[0],
        manifest_table_address=_U64.unpack_from(data, ABRM_MANIFEST_TABLE_ADDRESS)[0],
        sbrm_address=_U64.unpack_from(data, ABRM_SBRM_ADDRESS)[0],
        device_configuration=_U64.unpack_from(data, 0x01E0)[0],
        timestamp_increment_ns=_U64.unpack_from(data, 0x01FC)[0],
    )


@dataclass(frozen=True)
class Sbrm:
    """The USB3 Vision technology-specific bootstrap register map.

    Attributes
    ----------
    u3v_version
        Raw version register (u32).
    u3vcp_capability, u3vcp_configuration
        Raw bit fields (u64).
    max_command_transfer_length, max_ack_transfer_length
        Largest whole command / acknowledge packet, bytes.
    stream_channel_count
        Number of stream channels (0 = none).
    sirm_address, sirm_length
        SIRM base address and size in bytes.
    eirm_address, eirm_length
        EIRM base address and size in bytes (events are not implemented).
    iidc2_address
        IIDC2 register address (unused).
    current_speed
        Raw bus speed register.
    """

    u3v_version: int
    u3vcp_capability: int
    u3vcp_configuration: int
    max_command_transfer_length: int
    max_ack_transfer_length: int
    stream_channel_count: int
    sirm_address: int
    sirm_length: int
    eirm_address: int
    eirm_length: int
    iidc2_address: int
    current_speed: int


def decode_sbrm(data: bytes, device: str) -> Sbrm:
    """Decode the SBRM from the ``SBRM_SIZE`` bytes read at its base address.

    Raises
    ------
    ProtocolError
        Fewer than ``SBRM_SIZE`` bytes.
    """
    data = _require(data, SBRM_SIZE, "SBRM", device)
    return Sbrm(*_SBRM.unpack_from(data, 0))


@dataclass(frozen=True)
class Sirm:
    """The streaming interface register map.

    Attributes
    ----------
    si_info
        Raw SI info register; ``alignment`` decodes bits 24..31.
    si_control
        Raw SI control register (bit 0 = stream enable).
    required_payload_size, required_leader_size, required_trailer_size
        Sizes the device needs for one block, bytes.
    max_leader_size, payload_transfer_size, payload_transfer_count, final_transfer1_size,
    final_transfer2_size, max_trailer_size
        What the host last wrote (bytes; count is a number of transfers).
    """

    si_info: int
    si_control: int
    required_payload_size: int
    required_leader_size: int
    required_trailer_size: int
    max_leader_size: int
    payload_transfer_size: int
    payload_transfer_count: int
    final_transfer1_size: int
    final_transfer2_size: int
    max_trailer_size: int

    @property
    def alignment(self) -> int:
        """Transfer size alignment in bytes (``2 ** (si_info >> 24)``)."""
        return 1 << ((self.si_info >> 24) & 0xFF)

    @property
    def stream_enabled(self) -> bool:
        return bool(self.si_control & SI_CONTROL_STREAM_ENABLE)


def decode_sirm(data: bytes, device: str) -> Sirm:
    """Decode the SIRM from the ``SIRM_SIZE`` bytes read at its base address.

    Raises
    ------
    ProtocolError
        Fewer than ``SIRM_SIZE`` bytes, or a required size or alignment beyond the ``SIRM_MAX_*``
        bounds (a 2**255-byte alignment would size the stream's read buffers).
    """
    data = _require(data, SIRM_SIZE, "SIRM", device)
    sirm = Sirm(*_SIRM.unpack_from(data, 0))
    for what, value, bound in (("transfer alignment", sirm.alignment, SIRM_MAX_ALIGNMENT),
                               ("required leader size", sirm.required_leader_size, SIRM_MAX_LEADER_OR_TRAILER),
                               ("required trailer size", sirm.required_trailer_size, SIRM_MAX_LEADER_OR_TRAILER),
                               ("required payload size", sirm.required_payload_size, SIRM_MAX_PAYLOAD)):
        if value > bound:
            raise ProtocolError(device, f"SIRM {what} is {value} B; expected at most {bound} B")
    return sirm


@dataclass(frozen=True)
class ManifestEntry:
    """One entry of the manifest table: where the GenICam XML file lives.

    Attributes
    ----------
    file_version
        (major, minor, subminor).
    file_format
        ``MANIFEST_FORMAT_XML`` (0) or ``MANIFEST_FORMAT_ZIP`` (1); other values are kept as read.
    schema_version
        (major, minor) of the GenICam schema.
    address
        Register address of the file.
    size
        File size, bytes.
    sha1
        20-byte SHA-1 of the file (all zeros if the device does not provide one).
    """

    file_version: tuple[int, int, int]
    file_format: int
    schema_version: tuple[int, int]
    address: int
    size: int
    sha1: bytes


def decode_manifest_count(data: bytes, device: str) -> int:
    """The number of entries, from the first 8 bytes of the manifest table.

    Raises
    ------
    ProtocolError
        Fewer than 8 bytes.
    """
    return _U64.unpack_from(_require(data, MANIFEST_COUNT_SIZE, "manifest entry count", device), 0)[0]


def decode_manifest_entry(data: bytes, device: str) -> ManifestEntry:
    """Decode one 64-byte manifest entry.

    Raises
    ------
    ProtocolError
        Fewer than 64 bytes.
    """
    data = _require(data, MANIFEST_ENTRY_SIZE, "manifest entry", device)
    version, format_info, address, size, sha1, _reserved = _MANIFEST_ENTRY.unpack_from(data, 0)
    return ManifestEntry(
        file_version=(version >> 24, (version >> 16) & 0xFF, version & 0xFFFF),
        file_format=format_info & 0x3F,
        schema_version=(format_info >> 24, (format_info >> 16) & 0xFF),
        address=address,
        size=size,
        sha1=sha1,
    )


@dataclass(frozen=True)
class TransferSizes:
    """What the host writes into the SIRM before enabling the stream (all bytes except count).

    A block arrives as one leader transfer, ``payload_count`` transfers of ``payload_size``,
    ``final1_size`` and ``final2_size`` if non-zero, then one trailer transfer.
    """

    max_leader_size: int
    payload_size: int
    payload_count: int
    final1_size: int
    final2_size: int
    max_trailer_size: int

    @property
    def payload_capacity(self) -> int:
        """Bytes the payload transfers can hold: ``size * count + final1 + final2``."""
        return self.payload_size * self.payload_count + self.final1_size + self.final2_size


def _align_up(value: int, alignment: int) -> int:
    return -(-value // alignment) * alignment


def compute_transfer_sizes(payload_size: int, leader_size: int, trailer_size: int, alignment: int,
                           max_transfer_size: int = 1 << 20) -> TransferSizes:
    """Split a block's payload into aligned bulk transfers.

    The bulk of the payload goes into ``count`` equal transfers of at most ``max_transfer_size``
    (rounded down to the alignment); the aligned part of the rest into final transfer 1 and the last
    partial chunk, rounded up to the alignment, into final transfer 2. So
    ``size * count + final1 + final2 >= payload_size`` and exceeds it by less than ``alignment``.

    Parameters
    ----------
    payload_size
        Required payload size from the SIRM, bytes (>= 0).
    leader_size, trailer_size
        Required leader / trailer sizes from the SIRM, bytes; rounded up to the alignment.
    alignment
        Transfer alignment from the SIRM's SI info, bytes (a power of two).
    max_transfer_size
        Largest single bulk transfer the host wants, bytes (>= alignment).

    Returns
    -------
    TransferSizes

    Raises
    ------
    ValueError
        Negative sizes, an alignment that is not a power of two, or a maximum below the alignment.
    """
    if min(payload_size, leader_size, trailer_size) < 0:
        raise ValueError(f"sizes must be >= 0, got payload {payload_size}, leader {leader_size}, "
                         f"trailer {trailer_size}")
    if alignment < 1 or alignment & (alignment - 1):
        raise ValueError(f"alignment must be a power of two, got {alignment}")
    if max_transfer_size < alignment:
        raise ValueError(f"max_transfer_size {max_transfer_size} must be >= alignment {alignment}")
    size = min(payload_size, max_transfer_size) // alignment * alignment
    count = payload_size // size if size else 0
    remainder = payload_size - size * count
    final1 = remainder // alignment * alignment
    final2 = _align_up(remainder - final1, alignment)
    return TransferSizes(_align_up(leader_size, alignment), size, count, final1, final2,
                         _align_up(trailer_size, alignment))
