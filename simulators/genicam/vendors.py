"""Three real cameras' register maps, written from their GenApi XML (``../shared/data/external/genicam``).

Each table lists the registers behind the station's features (``Width``, ``Height``,
``PixelFormat``, ``ExposureTime``, ``TriggerMode``, ``TriggerSoftware``, ``AcquisitionStart``,
``AcquisitionStop``) and the SFNC features a GenTL producer sets (``AcquisitionMode``,
``PayloadSize``), with the inquiry words the XML reads for implemented / available / locked, the
selector's entries and the enumerations' per-entry bits. Limits are the simulator's choice (16 to
16384 pixels in steps of 4 or 8; exposure 10 µs to 30 s).

* FLIR Blackfly S BFS-U3-161S7M (USB3 Vision, little-endian): an inquiry word per feature, bit 31
  implemented, 30 available, 28 locked; ``ExposureTime`` an integer µs register behind a Converter;
  ``TriggerMode``'s address computed from ``TriggerSelector`` (FrameStart: block 1 of 0x20 bytes).
* Allied Vision Alvium 1800 U-811m (USB3 Vision, little-endian): ``StructReg`` inquiry tables at
  0x0080_0000 (bit 0 implemented, bit 1 available), a 64-bit float exposure, per-format words.
* Basler ace acA1920-25gm (GigE Vision, big-endian, so bit 0 is the most significant): the
  SFNC 1.x ``ExposureTimeAbs`` through a Converter of ``ExposureTimeRaw`` counts of a 20 µs time
  base, ``PixelFormat`` through an IntConverter onto Basler's own codes, selector-indexed trigger
  registers.
"""

from __future__ import annotations

from wavestack.simulators.genicam.personality import RegisterSpec as R
from wavestack.simulators.genicam.personality import VendorPersonality

_IMP_AVL_31_30 = 0xC000_0000  # FLIR and Basler inquiry words: implemented, available, not locked
MAX_SIDE = 16384


def _flir() -> VendorPersonality:
    registers = (
        R(0x81060, value=_IMP_AVL_31_30), R(0x81064, access="RW", feature="Height"), R(0x81068, value=16),
        R(0x8106C, value=MAX_SIDE), R(0x81070, value=4),
        R(0x81080, value=_IMP_AVL_31_30), R(0x81084, access="RW", feature="Width"), R(0x81088, value=16),
        R(0x8108C, value=MAX_SIDE), R(0x81090, value=4),
        R(0x86000, value=_IMP_AVL_31_30), R(0x86008, access="RW", feature="PixelFormat", codec="pixel_format"),
        R(0x8600C, value=0b11), R(0x86010, value=0b11), R(0x86014), R(0x86018),  # Mono8 bit 0, Mono16 bit 1
        R(0xC0000, value=_IMP_AVL_31_30), R(0xC0004, access="WO", feature="AcquisitionStart"),
        R(0xC0024, access="WO", feature="AcquisitionStop"),
        R(0xC00C8, access="RW", feature="AcquisitionMode"), R(0xC00CC, value=0b111), R(0xC00D0, value=0b111),
        R(0xC1000, value=_IMP_AVL_31_30), R(0xC1004, access="RW", feature="ExposureTime"),
        R(0xC1008, value=10), R(0xC100C, value=30_000_000),
        R(0xC8420, value=_IMP_AVL_31_30), R(0xC8424, access="RW", feature="TriggerMode"),
        R(0xC8820, value=_IMP_AVL_31_30), R(0xC8824, access="WO", feature="TriggerSoftware"),
        R(0xC8C00), R(0xC8C20, value=_IMP_AVL_31_30), R(0xC8C40),  # TriggerSelector: FrameStart only
        R(0x2000_2008, feature="PayloadSize"),
    )
    return VendorPersonality("flir-bfs", "u3v", "little", registers,
                             {"Mono8": 0x01080001, "Mono16": 0x01100007})


def _alvium() -> VendorPersonality:
    formats = {0x10101000: "Mono8", 0x1010100C: "Mono12", 0x10101018: "Mono16"}
    registers = [R(0x0080_0000 + 4 * k, value=0b11) for k in range(0x400)]  # every feature's inquiry word
    registers += [R(address, value=0b11 if address in formats else 0) for address in range(0x10101000, 0x101010B8, 4)]
    registers += [R(0x1030_0000 + 4 * k, value=0b11 if k == 3 else 0) for k in range(0x14)]  # selectors: FrameStart
    registers += [R(0x1021_0010 + 4 * k, value=0b11) for k in range(3)]  # AcquisitionMode entries
    registers += [R(0x1030_0090, value=0b11), R(0x1030_0094, value=0b11)]  # TriggerMode Off, On
    registers += [
        R(0x10100000, access="RW", feature="PixelFormat", codec="pixel_format"),
        R(0x10110000, value=MAX_SIDE), R(0x10110010, value=MAX_SIDE),
        R(0x10120000, access="RW", feature="Width"), R(0x10120010, value=16), R(0x10120030, value=8),
        R(0x10130000, access="RW", feature="Height"), R(0x10130010, value=16), R(0x10130030, value=8),
        R(0x10190000, access="RW"), R(0x101A0000, access="RW"),  # OffsetX, OffsetY
        R(0x101D0000, length=8, feature="PayloadSize", codec="u64"),
        R(0x10210000, access="RW", feature="AcquisitionMode"),
        R(0x10220000, access="WO", feature="AcquisitionStart"), R(0x10220010, access="WO", feature="AcquisitionStop"),
        R(0x10240000, length=8, access="RW", feature="ExposureTime", codec="f64"),
        R(0x10240010, length=8, value=10.0, codec="f64"), R(0x10240020, length=8, value=30e6, codec="f64"),
        R(0x10240030, length=8, value=0.5, codec="f64"),
        R(0x1030005C, access="RW", feature="TriggerMode"), R(0x103000DC, access="WO", feature="TriggerSoftware"),
    ]
    return VendorPersonality("alvium-1800u", "u3v", "little", tuple(registers),
                             {"Mono8": 0x01080001, "Mono12": 0x01100005, "Mono16": 0x01100007})


def _basler() -> VendorPersonality:
    registers = (
        R(0x10088, feature="PayloadSize"),
        R(0x30020), R(0x30024, access="RW", feature="PixelFormat", codec="pixel_format"),
        R(0x3002C, value=0x4400_0000), R(0x30030),  # Mono8 (bit 1) and Mono12 (bit 5), big-endian numbering
        R(0x30200, value=_IMP_AVL_31_30), R(0x30204, access="RW", feature="Width"), R(0x30208, value=16),
        R(0x3020C, value=MAX_SIDE), R(0x30210, value=8),
        R(0x30220, value=_IMP_AVL_31_30), R(0x30224, access="RW", feature="Height"), R(0x30228, value=16),
        R(0x3022C, value=MAX_SIDE), R(0x30230, value=8),
        R(0x40004, access="RW", feature="AcquisitionMode"), R(0x4000C),
        R(0x40024, access="RW", feature="AcquisitionStart"), R(0x40044, access="RW", feature="AcquisitionStop", command_value=0),
        R(0x40110), R(0x40210, value=1), R(0x40310),  # TriggerSelector entries: FrameStart only
        R(0x40204, access="RW", feature="TriggerMode"), R(0x4020C, value=_IMP_AVL_31_30),
        R(0x40220, access="RW", value=_IMP_AVL_31_30), R(0x40224, access="RW", feature="TriggerSoftware"),
        R(0x40440, value=0x4000_0000), R(0x40448, value=20_000),  # time base on (bit 1), 20 µs (in ns)
        R(0x40460, value=_IMP_AVL_31_30), R(0x40464, access="RW", feature="ExposureTime", codec="exposure_raw"),
        R(0x40468, value=1), R(0x4046C, value=1_500_000), R(0x40470, value=1),
    )
    return VendorPersonality("basler-ace-gige", "gige", "big", registers, {"Mono8": 1, "Mono12": 5},
                             exposure_unit_us=20.0)


PERSONALITIES = {p.name: p for p in (_flir(), _alvium(), _basler())}
