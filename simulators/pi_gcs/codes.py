"""GCS error codes the simulated controller sets, with PI's names and meanings.

Numbers and names are PI's General Command Set list, which is the same for every GCS controller
("The error codes listed here are those of the PI General Command Set", C-863.12 manual MS249E
v1.2.1, section 8.7 "Error Codes", p. 207; the same numbers appear in PI's GCS headers, e.g.
``PI_CNTR_PARAM_NR = 24``, ``PI_CNTR_DOUBLE_AXIS = 22``). Only the codes this simulator can set
are listed; a real controller knows many more.
"""

from __future__ import annotations

from typing import Final

__all__ = ["GCS_ERRORS", "NO_ERROR", "PARAM_SYNTAX", "UNKNOWN_COMMAND", "COMMAND_TOO_LONG",
           "MOVE_WITHOUT_REF_OR_NO_SERVO", "POS_OUT_OF_LIMITS", "VEL_OUT_OF_LIMITS", "SET_PIVOT_NOT_POSSIBLE",
           "STOP", "INVALID_AXIS_IDENTIFIER", "PARAM_OUT_OF_RANGE", "DOUBLE_AXIS", "PARAM_NR"]

NO_ERROR: Final = 0
PARAM_SYNTAX: Final = 1
UNKNOWN_COMMAND: Final = 2
COMMAND_TOO_LONG: Final = 3
MOVE_WITHOUT_REF_OR_NO_SERVO: Final = 5
POS_OUT_OF_LIMITS: Final = 7
VEL_OUT_OF_LIMITS: Final = 8
SET_PIVOT_NOT_POSSIBLE: Final = 9
STOP: Final = 10
INVALID_AXIS_IDENTIFIER: Final = 15
PARAM_OUT_OF_RANGE: Final = 17
DOUBLE_AXIS: Final = 22
PARAM_NR: Final = 24

#: code -> (PI's name, PI's meaning)
GCS_ERRORS: Final[dict[int, tuple[str, str]]] = {
    NO_ERROR: ("PI_CNTR_NO_ERROR", "No error"),
    PARAM_SYNTAX: ("PI_CNTR_PARAM_SYNTAX", "Parameter syntax error"),
    UNKNOWN_COMMAND: ("PI_CNTR_UNKNOWN_COMMAND", "Unknown command"),
    COMMAND_TOO_LONG: ("PI_CNTR_COMMAND_TOO_LONG", "Command length out of limits or command buffer overrun"),
    MOVE_WITHOUT_REF_OR_NO_SERVO: ("PI_CNTR_MOVE_WITHOUT_REF_OR_NO_SERVO",
                                   "Unallowable move attempted on unreferenced axis, or move attempted with servo off"),
    POS_OUT_OF_LIMITS: ("PI_CNTR_POS_OUT_OF_LIMITS", "Position out of limits"),
    VEL_OUT_OF_LIMITS: ("PI_CNTR_VEL_OUT_OF_LIMITS", "Velocity out of limits"),
    SET_PIVOT_NOT_POSSIBLE: ("PI_CNTR_SET_PIVOT_NOT_POSSIBLE", "Attempt to set pivot point while U,V and W not all 0"),
    STOP: ("PI_CNTR_STOP", "Controller was stopped by command"),
    INVALID_AXIS_IDENTIFIER: ("PI_CNTR_INVALID_AXIS_IDENTIFIER", "Invalid axis identifier"),
    PARAM_OUT_OF_RANGE: ("PI_CNTR_PARAM_OUT_OF_RANGE", "Parameter out of range"),
    DOUBLE_AXIS: ("PI_CNTR_DOUBLE_AXIS", "Axis identifier specified more than once"),
    PARAM_NR: ("PI_CNTR_PARAM_NR", "Incorrect number of parameters"),
}
