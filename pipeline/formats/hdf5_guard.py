"""Reading an HDF5 file in a child process, so that a damaged file cannot hang or crash the caller.

The HDF5 C library trusts the structures it finds in a file. Fuzzing our readers found a
``.datx`` whose damaged global heap makes reading a variable-length string attribute loop
forever inside the library (GIL held, no Python-level timeout can interrupt it), and such
libraries are known to crash on damaged files. :func:`read_guarded` runs a reader in a forked
child with a deadline: the parent gets the reader's value or its :class:`InputError`, or an
:class:`InputError` saying the file hung or crashed the library. The value crosses a pipe
(pickled), so the arrays are copied once.

On a platform without ``fork`` the reader runs in the calling process (no guard).
"""

from __future__ import annotations

import logging
import multiprocessing
import multiprocessing.connection
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from .errors import InputError

__all__ = ["DEFAULT_TIMEOUT_S", "read_guarded"]

logger = logging.getLogger(__name__)

T = TypeVar("T")

# A well-formed measured map (a few thousand pixels on a side) is read in well under a second;
# a minute is beyond any of them on a loaded machine and still bounds a hung read.
DEFAULT_TIMEOUT_S = 60.0


def _child(reader: Callable[[Path], T], path: Path, sender: multiprocessing.connection.Connection) -> None:
    try:
        result: tuple[str, object] = ("ok", reader(path))
    except InputError as error:
        result = ("error", str(error))
    except BaseException as error:  # noqa: BLE001 - everything crosses the pipe as an InputError
        result = ("error", f"{path}: damaged HDF5 file: {type(error).__name__}: {' '.join(str(error).split())}")
    try:
        sender.send(result)
    finally:
        sender.close()


def read_guarded(reader: Callable[[Path], T], path: Path, timeout_s: float = DEFAULT_TIMEOUT_S) -> T:
    """``reader(path)`` run in a forked child that must finish within ``timeout_s`` seconds.

    Parameters
    ----------
    reader : callable
        Reads the file; raises :class:`InputError` for a file it cannot use. Its value must
        pickle.
    path : Path
    timeout_s : float
        Seconds the child may take.

    Returns
    -------
    The reader's value.

    Raises
    ------
    InputError
        The reader's own, or naming the file when the child did not finish in time (killed)
        or died without an answer (a crash of the HDF5 library).
    """
    try:
        context = multiprocessing.get_context("fork")
    except ValueError:  # no fork on this platform: no guard
        return reader(path)
    receiver, sender = context.Pipe(duplex=False)
    process = context.Process(target=_child, args=(reader, path, sender), daemon=True)
    process.start()
    sender.close()
    try:
        if not receiver.poll(timeout_s):
            raise InputError(f"{path}: reading the HDF5 structure did not finish within {timeout_s:g} s; "
                             "the file is damaged")
        try:
            status, value = receiver.recv()
        except EOFError:
            process.join(timeout_s)
            raise InputError(f"{path}: the HDF5 library crashed reading the file (exit code {process.exitcode}); "
                             "the file is damaged") from None
    finally:
        receiver.close()
        if process.is_alive():
            process.kill()
        process.join()
        process.close()
    if status == "error":
        raise InputError(str(value))
    return value  # type: ignore[return-value]
