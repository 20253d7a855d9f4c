"""GCS 2.0 controller error codes, their meanings, and the typed error that carries them.

A PI controller keeps the code of the last error; ``ERR?`` answers it and resets it to 0. The
driver asks ``ERR?`` after every command that changes state and raises :class:`GcsError` for a
nonzero code. Only the codes below are given a meaning here (the ones a hexapod or a two-axis
stage driven by this package can plausibly set, and the ones the driver relies on: 10 after a
stop); any other code is reported with its number and a pointer to the controller's manual.

The meanings are PI's own wording, from the controller error list PI publishes with its EPICS
driver [1]_ (``translateerror.c``, generated from ``PIControllerErrors.h``) and named the same in
PI's Python library [2]_ (``gcserror.py``: ``E10_PI_CNTR_STOP`` and so on). Code 10 after ``#24``,
``STP`` or ``HLT`` is documented in PI's Python library (``StopAll``: "May raise
GCSError(E10_PI_CNTR_STOP)") and relied on by PI's EPICS hexapod driver [3]_ (``haltAxis``:
``#24`` then ``ERR?`` must read ``PI_CNTR_STOP``).

References
----------
.. [1] Physik Instrumente, ``translateerror.c`` and ``picontrollererrors.h`` (2011-2013, S. Rau),
   in epics-modules/motor, ``motorApp/PIGCS2Src/``.
.. [2] Physik Instrumente, PIPython, ``pipython/pidevice/gcserror.py`` and
   ``pipython/pidevice/gcs2/gcs2commands.py`` (``StopAll``).
.. [3] epics-modules/motor, ``motorApp/PIGCS2Src/PIHexapodController.cpp`` (``haltAxis``).
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Final

from wavestack.drivers.errors import ProtocolError

__all__ = ["GCS_ERRORS", "NO_ERROR", "STOPPED_BY_COMMAND", "GcsError", "error_meaning"]

NO_ERROR: Final = 0
#: Set by ``#24`` (stop all), ``STP`` and ``HLT``; read (and cleared) by the next ``ERR?``.
STOPPED_BY_COMMAND: Final = 10

#: Controller error code -> PI's meaning (see the module references).
GCS_ERRORS: Final = MappingProxyType({
    0: "No error",
    1: "Parameter syntax error",
    2: "Unknown command",
    3: "Command length out of limits or command buffer overrun",
    5: "Unallowable move attempted on unreferenced axis, or move attempted with servo off",
    7: "Position out of limits",
    8: "Velocity out of limits",
    9: "Attempt to set pivot point while U,V and W not all 0",
    10: "Controller was stopped by command",
    15: "Invalid axis identifier",
    17: "Parameter out of range",
    22: "Axis identifier specified more than once",
    23: "Illegal axis",
    24: "Incorrect number of parameters",
    25: "Invalid floating point number",
    26: "Parameter missing",
    27: "Soft limit out of range",
    34: "Command not allowed for selected stage(s)",
    45: "Referencing failed",
    50: "Attempt to reference axis with referencing disabled",
    52: "Controller detected communication error",
})


def error_meaning(code: int) -> str:
    """PI's meaning of a controller error code, or a pointer to the manual for an unlisted one.

    Examples
    --------
    >>> error_meaning(10)
    'Controller was stopped by command'
    >>> error_meaning(4242)
    'unlisted GCS error 4242 (see the controller manual)'
    """
    return GCS_ERRORS.get(code, f"unlisted GCS error {code} (see the controller manual)")


class GcsError(ProtocolError):
    """The controller reported a nonzero error code on ``ERR?``.

    Parameters
    ----------
    code
        The controller's error code (``ERR?`` answer), nonzero.
    meaning
        What it means; by default PI's wording (:func:`error_meaning`).
    device
        Who answered, for the message.
    command
        The command after which ``ERR?`` was asked, if known.

    Attributes
    ----------
    code, meaning, command
        As given.

    Examples
    --------
    >>> error = GcsError(7, command="MOV X 99")
    >>> error.code, error.meaning
    (7, 'Position out of limits')
    """

    def __init__(self, code: int, meaning: str | None = None, *, device: str = "PI GCS controller",
                 command: str | None = None) -> None:
        self.code = int(code)
        self.meaning = error_meaning(self.code) if meaning is None else meaning
        self.command = command
        after = f" after {command!r}" if command else ""
        super().__init__(device, f"controller error {self.code} ({self.meaning}){after}; expected 0 on ERR?")
