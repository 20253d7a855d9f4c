"""Checks of an HDF5 dataset before it is read: shape, type, and the bytes it may make a reader allocate."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from .errors import InputError
from .limits import MAX_COMPRESSION_RATIO, check_allocation, format_bytes

__all__ = ["check_dataset_size"]


def check_dataset_size(path: Path, node: h5py.Dataset, max_bytes: int | None) -> None:
    """Refuse a 2-D real dataset larger than the memory budget or than its stored bytes justify.

    The dataset is read as its own dtype and copied to float64, so the allocation is
    ``rows * cols * (itemsize + 8)`` bytes. An uncompressed dataset must store all of its bytes,
    a filtered (compressed) one at least ``1 / MAX_COMPRESSION_RATIO`` of them: a dataset whose
    chunks were never written (read back as the fill value) or that lives in an external file
    is refused.
    """
    if node.shape is None or len(node.shape) != 2 or 0 in node.shape or node.dtype.kind not in "iuf":
        raise InputError(f"{path}: {node.name} must be a 2-D real array, got shape {node.shape} dtype {node.dtype}")
    check_allocation(path, f"{node.name} dataset", node.shape, node.dtype.itemsize + 8, max_bytes)
    needed = int(np.prod(node.shape)) * node.dtype.itemsize
    stored = int(node.id.get_storage_size())
    compressed = bool(node.id.get_create_plist().get_nfilters())
    justified = stored * MAX_COMPRESSION_RATIO if compressed else stored
    if needed > justified:
        raise InputError(
            f"{path}: {node.name} declares {node.shape[0]} x {node.shape[1]} values ({format_bytes(needed)}) but the "
            f"file stores {format_bytes(stored)} of them; expected a complete dataset in the file")
