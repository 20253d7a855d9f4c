"""What a fitter is built from: every setting of ``build_fitter`` in one checked value.

:func:`build_request` checks the settings once and returns a :class:`BuildRequest`; the build
(:mod:`wavestack.pipeline.fit.build`) reads it, ``auto`` and the advice on a failed build derive
the requests they try from it (:meth:`BuildRequest.trying`), and :attr:`BuildRequest.projection`
says, once, how the fitter will project frames: by separable moments or by a stored operator.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import DTypeLike, NDArray

from .._checks import is_integer, one_of
from ..zernike import default_normalisation
from .annulus import check_obscuration
from .auto import AUTO
from .methods import METHODS, MappingOptions
from .physical_terms import physical_term_names
from .results import Pupil

#: The methods whose columns are polynomials in pixel coordinates: they may refit by moments.
MOMENT_METHODS = ("circle", "qr", "annulus")

_ORDERINGS = ("noll", "ansi", "fringe")
_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))
_FALLBACKS = (None, "qr")


@dataclass(frozen=True, eq=False)
class BuildRequest:
    """The checked settings of one fitter build (see :func:`~wavestack.pipeline.build_fitter`).

    Attributes
    ----------
    method : str
        A concrete method, or ``"auto"`` until the build chooses one.
    modes : int
    ordering : {"noll", "ansi", "fringe"}
    pupil : Pupil or (cx, cy, r) or None
        The pupil as given (None: the aperture's enclosing circle).
    dtype : numpy dtype
        float32 or float64: the stored operator's type.
    normalisation : {"rms", "edge"}
    remove : {"ptt", "pttp"} or None
    mapping : MappingOptions
        The mapped methods' settings.
    fit_mask : ndarray of bool or None
        The pixels to fit when they are not the aperture's (resolved against it).
    refit : {"auto", "moments", "operator"}
    obscuration : float or None
        ``annulus`` only: the obscuration ratio given.
    """

    method: str
    modes: int
    ordering: str
    pupil: Pupil | tuple[float, float, float] | None
    dtype: np.dtype
    normalisation: str
    remove: str | None
    mapping: MappingOptions
    fit_mask: NDArray[np.bool_] | None
    refit: str
    obscuration: float | None

    @property
    def projection(self) -> Literal["moments", "operator"]:
        """How frames will be projected: ``"moments"`` for a polynomial method unless the operator
        is asked for (the build falls back to the operator where ``refit="auto"`` and moments would
        lose precision), else ``"operator"``."""
        return "moments" if self.method in MOMENT_METHODS and self.refit != "operator" else "operator"

    @property
    def user_pupil(self) -> bool:
        """The pupil was given (valid pixels outside it are left out of the fit)."""
        return self.pupil is not None

    def trying(self, method: str, **changes: object) -> BuildRequest:
        """The same request for one concrete ``method`` (and, e.g., another ``modes``)."""
        return dataclasses.replace(self, method=method, **changes)


def build_request(
    method: str,
    modes: int,
    ordering: str,
    pupil: Pupil | tuple[float, float, float] | None,
    dtype: DTypeLike,
    *,
    normalisation: str | None,
    remove: str | None,
    laplacian: str,
    mesh_vertices: int,
    angular_balance: bool,
    fallback: str | None,
    refit: str,
    obscuration: float | None,
) -> BuildRequest:
    """The settings of ``build_fitter`` checked, as one :class:`BuildRequest` (``fit_mask`` None:
    the caller resolves it against the aperture).

    Raises
    ------
    ValueError
        For a setting out of its range; the message names it and what was expected.
    """
    dtype = np.dtype(dtype)
    one_of(method, "method", (AUTO, *METHODS), voice="expected")
    if obscuration is not None:
        check_obscuration(obscuration)
        if method != "annulus":
            raise ValueError(f"obscuration: only the 'annulus' method takes an obscuration ratio, got method {method!r}")
    if not is_integer(modes) or modes < 1:
        raise ValueError(f"modes: expected a positive integer, got {modes!r}")
    one_of(ordering, "ordering", _ORDERINGS, voice="expected")
    if dtype not in _DTYPES:
        raise ValueError(f"dtype: expected float32 or float64, got {dtype}")
    if fallback not in _FALLBACKS:
        raise ValueError(f"fallback: expected None or 'qr', got {fallback!r}")
    normalisation = normalisation or default_normalisation(ordering)
    if normalisation not in ("rms", "edge"):
        raise ValueError(f"normalisation: expected 'rms' or 'edge', got {normalisation!r}")
    if remove is not None:
        physical_term_names(remove)
    one_of(refit, "refit", ("auto", "moments", "operator"), voice="expected")
    return BuildRequest(
        method=method, modes=int(modes), ordering=ordering, pupil=pupil, dtype=dtype, normalisation=normalisation,
        remove=remove, mapping=MappingOptions(laplacian=laplacian, mesh_vertices=mesh_vertices,
                                              angular_balance=bool(angular_balance)),
        fit_mask=None, refit=refit, obscuration=obscuration,
    )
