"""Saving fitters to ``.npz`` files keyed by aperture and settings, so a station reuses them.

A fitter for a mapped method costs a mesh, a flow and several sparse solves to build; a station
that sees the same aperture again (after a restart, or when an obscuration comes back) loads it
instead. The file holds everything the per-frame path needs (operator, normal equations,
coefficient maps, basis and diagnostics) and the mask; the mesh and map themselves are not kept,
so a loaded fitter has ``mapping = None``.
"""

from __future__ import annotations

import hashlib
import json
import logging
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..aperture import Aperture
from .build import build_fitter
from .fitter import Fitter
from .moment_projection import MomentProjection, MomentState
from .operator_projection import OperatorProjection
from .normal_equations import NormalEquations
from .results import FitBasis, FitterDiagnostics, Pupil

logger = logging.getLogger(__name__)

# 2: moment fitters (no operator; the fitted-pixel mask, strips and coefficients instead), and the
# fit dtype recorded. Files of format 1 are rebuilt by the store (their key names the version).
FORMAT_VERSION = 2


def fitter_key(mask: NDArray, settings: Mapping[str, Any]) -> str:
    """A hex digest naming a fitter: the mask's shape and pixels, and the build settings.

    Parameters
    ----------
    mask : ndarray, shape (rows, cols)
        Valid pixels (non-zero).
    settings : mapping
        The keyword arguments of :func:`build_fitter` (JSON-serialisable; dtypes by name).

    Returns
    -------
    str
        64 hex digits (SHA-256).
    """
    mask = np.asarray(mask) != 0
    digest = hashlib.sha256()
    digest.update(f"wavestack-fitter-{FORMAT_VERSION}:{mask.shape}".encode())
    digest.update(np.packbits(mask).tobytes())
    digest.update(json.dumps(_jsonable(settings), sort_keys=True).encode())
    return digest.hexdigest()


def _jsonable(settings: Mapping[str, Any]) -> dict[str, Any]:
    out = {}
    for key, value in settings.items():
        if isinstance(value, Pupil):
            value = value.as_dict()
        elif isinstance(value, (type, np.dtype)):
            value = np.dtype(value).name
        elif isinstance(value, tuple):
            value = list(value)
        out[key] = value
    return out


def save_fitter(fitter: Fitter, path: str | Path) -> None:
    """Write a fitter to an ``.npz`` file (see :func:`load_fitter`)."""
    state = fitter.export_state()
    basis = state.pop("basis")
    diagnostics = state.pop("diagnostics")
    meta = {
        "format": FORMAT_VERSION,
        "basis": {**basis, "pupil": basis["pupil"]},
        "diagnostics": diagnostics,
        "removal": state.pop("removal"),
        "dtype": state.pop("dtype"),
        "min_hole_area_px": fitter.aperture.min_hole_area_px,
        "mask_shape": list(fitter.aperture.shape),
    }
    arrays = {k: v for k, v in state.items() if v is not None}
    arrays["mask_bits"] = np.packbits(fitter.aperture.mask)
    with open(path, "wb") as handle:
        np.savez(handle, meta=np.array(json.dumps(meta)), **arrays)


def load_fitter(path: str | Path) -> Fitter:
    """Read a fitter written by :func:`save_fitter`.

    Raises
    ------
    ValueError
        If the file is not a wavestack fitter of this format version.
    """
    with np.load(path, allow_pickle=False) as data:
        try:
            meta = json.loads(str(data["meta"]))
        except KeyError:
            raise ValueError(f"{path}: not a wavestack fitter file (no metadata)") from None
        if meta.get("format") != FORMAT_VERSION:
            raise ValueError(f"{path}: fitter format {meta.get('format')}, expected {FORMAT_VERSION}")
        arrays = {key: data[key] for key in data.files if key != "meta"}
    shape = tuple(meta["mask_shape"])
    bits = arrays.pop("mask_bits")
    mask = np.unpackbits(bits, count=shape[0] * shape[1]).reshape(shape).astype(bool)
    aperture = Aperture.from_mask(mask, min_hole_area_px=meta["min_hole_area_px"])
    basis = dict(meta["basis"])
    basis["pupil"] = Pupil(**basis["pupil"])
    basis["modes"] = tuple(tuple(mode) for mode in basis["modes"])
    return Fitter(
        aperture=aperture,
        projection=_projection(arrays, shape),
        equations=NormalEquations(
            arrays.pop("gram"), arrays.pop("column_sums"),
            int(arrays.pop("n_basis")), int(arrays.pop("n_samples")),
        ),
        coefficient_transform=arrays.pop("coefficient_transform"),
        from_coefficients=arrays.pop("from_coefficients"),
        basis=FitBasis(**basis),
        diagnostics=FitterDiagnostics(**meta["diagnostics"]),
        dtype=np.dtype(meta["dtype"]),
        circle_transform=arrays.pop("circle_transform", None),
        removal=meta["removal"],
        removal_transform=arrays.pop("removal_transform", None),
    )


def _projection(arrays: dict[str, NDArray], shape: tuple[int, ...]) -> MomentProjection | OperatorProjection:
    """The stored projection: a moment fitter's mask, strips and coefficients, or the operator."""
    if "moment_transform" in arrays:
        bits = arrays.pop("moment_mask_bits")
        mask = np.unpackbits(bits, count=shape[0] * shape[1]).reshape(shape).astype(bool)
        return MomentProjection(MomentState(mask, arrays.pop("moment_strips").astype(np.int64),
                                            int(arrays.pop("moment_degree")), arrays.pop("moment_transform")))
    operator = arrays.pop("operator")
    if arrays.pop("operator_mode_major")[()]:
        operator = operator.T
    return OperatorProjection((int(shape[0]), int(shape[1])), arrays.pop("flat_index").astype(np.intp), operator)


class FitterStore:
    """A folder of saved fitters: load the one for this aperture and settings, or build it.

    Parameters
    ----------
    directory : str or Path
        Where the ``.npz`` files live; created if missing.
    """

    def __init__(self, directory: str | Path) -> None:
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)

    def path_for(self, mask: NDArray, settings: Mapping[str, Any]) -> Path:
        """File that holds (or would hold) the fitter for this mask and settings."""
        return self.directory / f"fitter-{fitter_key(mask, settings)}.npz"

    def get_or_build(self, aperture_or_mask: Aperture | NDArray, **settings: Any) -> Fitter:
        """Load the saved fitter for this aperture and settings, or build and save it.

        Parameters
        ----------
        aperture_or_mask : Aperture or ndarray
        **settings
            Keyword arguments of :func:`build_fitter`.
        """
        aperture = aperture_or_mask if isinstance(aperture_or_mask, Aperture) else Aperture.from_mask(aperture_or_mask)
        path = self.path_for(aperture.mask, settings)
        if path.exists():
            try:
                fitter = load_fitter(path)
                logger.info("loaded fitter %s", path.name)
                return fitter
            except (ValueError, OSError, KeyError) as error:
                logger.warning("ignoring unreadable fitter file %s: %s", path, error)
        fitter = build_fitter(aperture, **settings)
        temporary = path.with_suffix(".tmp")
        save_fitter(fitter, temporary)
        temporary.replace(path)  # atomic: a reader never sees half a file
        return fitter
