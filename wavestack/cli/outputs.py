"""Output files of the commands, checked before anything is computed or any device is opened.

A command that writes a file (``--save-fit``, ``--save-map``, ``--record``) checks the path first,
so that a typo costs nothing: not a fit of a large map, not a station run whose devices were all
opened. A path is accepted when its folder exists and is writable and the path is either absent
or a writable regular file (it is then replaced). A directory, a device (``/dev/null``), a pipe
or a socket is refused: ``numpy.save`` would append ``.npy`` to ``/dev/null`` and write a
regular file beside the device, and HDF5 cannot write to either.
"""

from __future__ import annotations

import json
import math
import os
import stat
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wavestack.pipeline import InputError
from wavestack.station import json_ready

__all__ = ["check_output_file", "check_plots_folder", "json_text", "require_finite", "save_npy"]


def check_output_file(path: str | Path, option: str) -> Path:
    """The path of an output file, once it can be written.

    Parameters
    ----------
    path : str or Path
        As given on the command line.
    option : str
        The option that gave it (``--save-fit``), named in the message.

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Naming the path and the option: an empty path, a folder that does not exist or is not
        writable, a directory, a device, pipe or socket, or an existing file that is not
        writable.
    """
    text = str(path)
    if not text.strip():
        raise InputError(f"{option} {text!r}: expected a file path")
    target = Path(text)
    folder = target.parent
    try:
        mode = os.stat(target).st_mode
    except FileNotFoundError:
        mode = None
    except OSError as error:
        raise InputError(f"{target}: {option} cannot be checked ({error.strerror})") from None
    if mode is not None and stat.S_ISDIR(mode):
        raise InputError(f"{target}: {option} names a directory; expected a file path")
    if mode is not None and not stat.S_ISREG(mode):
        raise InputError(f"{target}: {option} names a device, pipe or socket, not a regular file; expected a file path")
    if not folder.is_dir():
        raise InputError(f"{target}: {option} folder {folder} does not exist; expected an existing folder")
    if not os.access(folder, os.W_OK | os.X_OK) or (mode is not None and not os.access(target, os.W_OK)):
        raise InputError(f"{target}: {option} is not writable (permission denied)")
    return target


def check_plots_folder(text: str) -> Path:
    """The ``--plots`` folder: an existing writable folder, or a new one whose parent is writable (not created yet)."""
    folder = Path(text)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"--plots {folder}: not a folder; expected a folder for the figures")
    if folder.is_dir():
        if not os.access(folder, os.W_OK | os.X_OK):
            raise InputError(f"--plots {folder}: cannot write in this folder")
        return folder
    parent = folder.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"--plots {folder}: folder {parent} does not exist or is not writable; expected a folder "
                         "that exists or can be made")
    return folder


def save_npy(path: Path, array: NDArray) -> None:
    """Write ``array`` to exactly ``path`` (``numpy.save`` on a name would append ``.npy``)."""
    with open(path, "wb") as stream:
        np.save(stream, array)


def json_text(report: Any) -> str:
    """``report`` as strict JSON: a float that is not finite becomes ``null``, never a bare ``NaN``.

    The commands refuse inputs whose results would not be finite (a coefficient, an RMS); what
    may still be infinite is a diagnostic (a condition number), which ``null`` marks as "not a
    number" as the JSON standard (RFC 8259, section 6) allows no other way.
    """
    return json.dumps(json_ready(report), allow_nan=False)


def require_finite(source: str, what: str, values: ArrayLike) -> None:
    """Refuse a result that is not finite (an input of extreme magnitude or a degenerate fit).

    Raises
    ------
    InputError
        Naming ``source`` and what was not finite.
    """
    array = np.asarray(values, dtype=np.float64)
    if not np.isfinite(array).all():
        raise InputError(f"{source}: the {what} is not finite (overflow); expected a map of measurement-sized values")
