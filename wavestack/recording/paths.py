"""Check where a recording will go before any device is opened (``wavestack run --record FILE.h5``)."""

from __future__ import annotations

import os
from pathlib import Path

from wavestack.pipeline import InputError


def check_recording_path(path: str | Path, *, overwrite: bool = False) -> Path:
    """The path a new recording can be created at, checked without touching the disk.

    Parameters
    ----------
    path
        Where ``--record`` asks the recording to go.
    overwrite
        Accept an existing regular file (it will be replaced).

    Returns
    -------
    Path
        ``path`` as given (not resolved, so messages show what the user typed).

    Raises
    ------
    InputError
        A directory, a device or other non-regular file (``/dev/null``), an existing file without
        ``overwrite``, a missing parent folder, or a folder this process cannot write in; the
        message names the path and what was expected.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     print(check_recording_path(f"{folder}/run.h5").name)
    run.h5
    """
    target = Path(path)
    expected = "expected a new file in an existing, writable folder"
    if target.is_dir():
        raise InputError(f"--record {target}: is a directory; {expected}")
    if target.exists() or target.is_symlink():
        if not target.is_file():
            raise InputError(f"--record {target}: not a regular file (a device, pipe or dangling link); {expected}")
        if not overwrite:
            raise InputError(f"--record {target}: a file already exists; refusing to overwrite a recording")
    folder = target.parent
    if not folder.is_dir():
        raise InputError(f"--record {target}: folder {folder} does not exist; {expected}")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"--record {target}: cannot write in folder {folder}; {expected}")
    return target
