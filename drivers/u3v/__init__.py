"""USB3 Vision camera driver (GenCP control + one image stream) over pyusb.

Sans-I/O modules, each pure and fuzzable:

* :mod:`~wavestack.drivers.u3v.gencp` — READMEM/WRITEMEM commands, acknowledges, status codes.
* :mod:`~wavestack.drivers.u3v.bootstrap` — ABRM, SBRM, SIRM, manifest, SIRM transfer sizes.
* :mod:`~wavestack.drivers.u3v.image_block` — leader, trailer, pixel formats, payload decoding.
* :mod:`~wavestack.drivers.u3v.stream` — block assembly (re-exports the ``image_block`` names).

and the I/O around them:

* :mod:`~wavestack.drivers.u3v.control` — the locked GenCP control channel over the USB endpoints.
* :mod:`~wavestack.drivers.u3v.connection` — finding, claiming and releasing the camera.
* :mod:`~wavestack.drivers.u3v.register_port` — the register port the GenICam node map reads through.
* :mod:`~wavestack.drivers.u3v.acquisition` — enabling the stream, the reader thread, counters.
* :mod:`~wavestack.drivers.u3v.driver` with :class:`U3VCamera`, which holds the state::

    with U3VCamera.open(serial="SN1", timeout_s=2.0) as camera:
        camera.set_pixel_format("Mono12", timeout_s=1.0)
        camera.start()
        frame = camera.read_frame(timeout_s=1.0)
"""

from __future__ import annotations

from wavestack.drivers.u3v.bootstrap import (Abrm, ManifestEntry, Sbrm, Sirm, TransferSizes,
                                             compute_transfer_sizes)
from wavestack.drivers.u3v.driver import U3VCamera, U3VCounters
from wavestack.drivers.u3v.gencp import Acknowledge, GenCPStatus, status_name
from wavestack.drivers.u3v.stream import (AssembledBlock, BlockAssembler, DiscardedBlock, Leader, Trailer,
                                          decode_pixels, parse_leader, parse_trailer)

__all__ = [
    "Abrm", "Acknowledge", "AssembledBlock", "BlockAssembler", "DiscardedBlock",
    "GenCPStatus", "Leader", "ManifestEntry", "Sbrm", "Sirm", "Trailer", "TransferSizes", "U3VCamera",
    "U3VCounters", "compute_transfer_sizes", "decode_pixels", "parse_leader", "parse_trailer",
    "status_name",
]
