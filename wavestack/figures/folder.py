"""The folder a ``--plots DIR`` option writes into, checked (and made) before any work."""

from __future__ import annotations

import os
from pathlib import Path

from wavestack.pipeline import InputError

__all__ = ["check_plot_folder"]


def check_plot_folder(path: str | Path, option: str) -> Path:
    """The folder ``path``, created if it is missing, once figures can be written into it.

    Parameters
    ----------
    path : str or Path
        As given on the command line.
    option : str
        The option that gave it (``--plots``), named in the message.

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Naming the path and the option: an empty path, a path that exists but is not a folder,
        a folder (or the missing folder's parent) that does not exist or is not writable.

    Example
    -------
    >>> check_plot_folder("", "--plots")
    Traceback (most recent call last):
    ...
    wavestack.pipeline.formats.errors.InputError: --plots '': expected a folder path
    """
    text = str(path)
    if not text.strip():
        raise InputError(f"{option} {text!r}: expected a folder path")
    folder = Path(text)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder}: {option} names a file, not a folder; expected a folder path")
    if not folder.exists():
        if not folder.parent.is_dir():
            raise InputError(f"{folder}: {option} parent folder {folder.parent} does not exist; "
                             "expected an existing folder or one inside an existing folder")
        try:
            folder.mkdir()
        except OSError as error:
            raise InputError(f"{folder}: {option} cannot be created ({error.strerror})") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{folder}: {option} is not writable (permission denied)")
    return folder
