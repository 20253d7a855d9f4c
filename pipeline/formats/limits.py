"""How much memory an input may make wavestack allocate, and the check every reader applies.

A file declares the size of its arrays in a header (a MetroPro header, an HDF5 dataspace, an
image header) before any array is allocated. A hostile or damaged file can declare 40000 x 40000
pixels in 6 KB; a reader that believes it either fails deep inside numpy with a traceback or
takes the machine's memory. Every reader therefore checks the declared size against a budget
before it allocates:

* the **memory budget**: half of the memory the kernel says is available now (``MemAvailable``
  in ``/proc/meminfo``; ``os.sysconf`` physical pages where that file does not exist), and at
  least :data:`MIN_BUDGET_BYTES`. Half, because an analysis holds several arrays of the input's
  size at once (the float64 copy, the phase, the unwrapped map, the fit's residual);
* what the **file justifies**: an uncompressed array cannot be larger than the bytes that hold
  it, and a compressed one not more than :data:`MAX_COMPRESSION_RATIO` times them (deflate's
  limit is 1032:1).

The budget is computed when a reader is called, never stored (no module state); callers that
want another bound (the property tests, a service with a quota) pass ``max_bytes``.
"""

from __future__ import annotations

import os
from pathlib import Path

from .errors import InputError

__all__ = ["MAX_COMPRESSION_RATIO", "MIN_BUDGET_BYTES", "check_allocation", "format_bytes", "memory_budget_bytes"]

MIN_BUDGET_BYTES = 256 * 2**20  # a budget never below 256 MiB (a 4k x 4k float64 map is 128 MiB)
MAX_COMPRESSION_RATIO = 1100  # deflate expands at most 1032:1; a little headroom for HDF5 chunk headers


def memory_budget_bytes() -> int:
    """Bytes one input may make wavestack allocate: half the memory available now.

    Returns
    -------
    int
        ``MemAvailable / 2`` from ``/proc/meminfo`` (Linux), else half the physical memory
        (``os.sysconf``), and at least :data:`MIN_BUDGET_BYTES`.
    """
    available = _available_bytes()
    return max(MIN_BUDGET_BYTES, available // 2)


def _available_bytes() -> int:
    try:
        with open("/proc/meminfo", encoding="ascii") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (OSError, ValueError, AttributeError):
        return MIN_BUDGET_BYTES


def format_bytes(count: float) -> str:
    """``count`` bytes in the largest binary unit below it, e.g. ``'11.9 GiB'``."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(count) < 1024 or unit == "TiB":
            return f"{count:.0f} {unit}" if unit == "B" else f"{count:.1f} {unit}"
        count /= 1024
    raise AssertionError("unreachable")


def check_allocation(path: str | Path, what: str, shape: tuple[int, ...], itemsize: int,
                     max_bytes: int | None = None) -> None:
    """Refuse an array of ``shape`` x ``itemsize`` bytes that exceeds the memory budget.

    Parameters
    ----------
    path : str or Path
        The file that declares the array (named in the message).
    what : str
        What the array is, e.g. ``"surface"`` or ``"image"``.
    shape : tuple of int
        The declared shape.
    itemsize : int
        Bytes per element of the array that will be allocated (8 for the float64 copy).
    max_bytes : int, optional
        The bound; default :func:`memory_budget_bytes`.

    Raises
    ------
    InputError
        Naming the file, the declared shape, the bytes it needs and the budget.
    """
    needed = itemsize
    for side in shape:
        needed *= int(side)
    limit = memory_budget_bytes() if max_bytes is None else int(max_bytes)
    if needed > limit:
        dims = " x ".join(str(int(s)) for s in shape)
        source = " (half the memory available)" if max_bytes is None else ""
        raise InputError(f"{path}: the {what} declares {dims} values ({format_bytes(needed)}), more than the "
                         f"memory budget of {format_bytes(limit)}{source}")
