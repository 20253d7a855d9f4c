"""Where a processor gets its fitters: the settings they are built with, the choice it is handed, and the source.

A processor never builds its configured fitter itself: it is given a :class:`FitterSource` and asks
it for the fitter of each new aperture. The station's source builds the configured method on a
worker thread and hands out a ``qr`` stand-in meanwhile (``wavestack.station.FitterCache``: the
threads stay in the station); ``analyze``, ``replay`` and ``batch`` use :class:`SyncFitterSource`,
which builds it at once. Either way the fitter of one aperture and one method is built by
:func:`build_configured`, so the numbers do not depend on who built it.

The protocol is the instrument's, not the interferometer's: a Shack-Hartmann processor's
reconstructors per set of lit lenslets can come from a source of the same shape.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..aperture import Aperture
from ..fit import Fitter, build_fitter

__all__ = ["FALLBACK_METHOD", "FitSettings", "FitterChoice", "FitterSource", "SyncFitterSource", "build_configured"]

#: The method that stands in while the configured one is being built (exact for the modes it fits).
FALLBACK_METHOD = "qr"


@dataclass(frozen=True)
class FitSettings:
    """What a fitter is built with (see :func:`wavestack.pipeline.build_fitter`).

    Attributes
    ----------
    method : str
        ``csf-qcm``, ``conformal``, ``qr``, ``circle``, ``annulus`` or ``auto``.
    modes : int
    ordering : str
        ``noll``, ``ansi`` or ``fringe``.
    remove : {"ptt", "pttp"} or None
        Physical terms removed before the fit.
    mesh_vertices : int
        Mesh size of a mapped method.
    obscuration : float or None
        ``annulus`` only: inner over outer radius (None: measured).
    dtype : {"float32", "float64"}
        The fitter's operator and per-frame product.
    """

    method: str = "csf-qcm"
    modes: int = 36
    ordering: str = "noll"
    remove: str | None = "ptt"
    mesh_vertices: int = 15000
    obscuration: float | None = None
    dtype: str = "float32"


@dataclass(frozen=True, eq=False)
class FitterChoice:
    """The fitter to use for one result.

    Attributes
    ----------
    fitter : Fitter
    kind : str
        The method that built it (``csf-qcm``, ``qr``, ``circle``, ``annulus``, ``conformal``).
    fallback : bool
        True when it stands in for the configured method (while that one is being built, or where
        the configured map could not be made).
    aperture_id : int
        Which aperture (counted from 0 per source) it was built for.
    """

    fitter: Fitter
    kind: str
    fallback: bool
    aperture_id: int


class FitterSource(Protocol):
    """Hands a processor the fitter of its current aperture."""

    def new_aperture(self, aperture: Aperture, *, fit_mask: NDArray[np.bool_] | None = None,
                     method: str | None = None) -> FitterChoice:
        """Start a new aperture; the fitter to use at once.

        ``fit_mask``: the pixels to fit, when not the whole aperture (see ``build_fitter``);
        ``method``: build that method, synchronously, instead of the configured one.
        """

    def current(self) -> FitterChoice | None:
        """The best fitter for the current aperture so far (None before any aperture)."""

    def use_method(self, method: str) -> FitterChoice:
        """Switch the current aperture to a fitter of ``method``, built synchronously once."""


def build_configured(aperture: Aperture, settings: FitSettings, method: str,
                     fit_mask: NDArray[np.bool_] | None = None) -> Fitter:
    """The fitter of ``method`` on ``aperture`` (fitting ``fit_mask``) with ``settings`` (a mapped method falls back to ``qr``).

    Example
    -------
    >>> rows, cols = np.mgrid[:40, :40]
    >>> disk = Aperture.from_mask(np.hypot(rows - 19.5, cols - 19.5) < 18)
    >>> build_configured(disk, FitSettings(method="circle", modes=10), "circle").n_modes
    10
    """
    s = settings
    return build_fitter(aperture, method=method, modes=s.modes, ordering=s.ordering, remove=s.remove,
                        mesh_vertices=s.mesh_vertices, obscuration=s.obscuration, dtype=np.dtype(s.dtype), fit_mask=fit_mask,
                        fallback=FALLBACK_METHOD if method in ("csf-qcm", "conformal", "auto") else None)


def choice_of(fitter: Fitter, configured: str, aperture_id: int) -> FitterChoice:
    """The choice of a built fitter: its method, and whether it stands in for ``configured``."""
    built = str(fitter.diagnostics.method)
    fallback = built == FALLBACK_METHOD if configured == "auto" else built != configured
    return FitterChoice(fitter, built, fallback, aperture_id)


class SyncFitterSource:
    """A fitter source that builds every fitter at once, on the caller's thread (analyze, replay, batch).

    Parameters
    ----------
    settings : FitSettings

    Example
    -------
    >>> rows, cols = np.mgrid[:40, :40]
    >>> source = SyncFitterSource(FitSettings(method="circle", modes=6))
    >>> choice = source.new_aperture(Aperture.from_mask(np.hypot(rows - 19.5, cols - 19.5) < 18))
    >>> choice.kind, choice.fallback, source.current() is choice
    ('circle', False, True)
    """

    def __init__(self, settings: FitSettings) -> None:
        self.settings = settings
        self._aperture_id = -1
        self._aperture: Aperture | None = None
        self._fit_mask: NDArray[np.bool_] | None = None
        self._current: FitterChoice | None = None
        self._built: dict[str, FitterChoice] = {}  # fitters of the current aperture, by method asked for

    def new_aperture(self, aperture: Aperture, *, fit_mask: NDArray[np.bool_] | None = None,
                     method: str | None = None) -> FitterChoice:
        self._aperture_id += 1
        self._aperture, self._fit_mask = aperture, fit_mask
        kind = method or self.settings.method
        fitter = build_configured(aperture, self.settings, kind, fit_mask)
        choice = choice_of(fitter, self.settings.method, self._aperture_id)
        self._current, self._built = choice, {kind: choice}
        return choice

    def current(self) -> FitterChoice | None:
        return self._current

    def use_method(self, method: str) -> FitterChoice:
        if self._aperture is None or self._current is None:
            raise RuntimeError("use_method before any aperture")
        cached = self._built.get(method)
        if cached is None:
            fitter = build_configured(self._aperture, self.settings, method, self._fit_mask)
            cached = choice_of(fitter, self.settings.method, self._current.aperture_id)
            self._built[method] = cached
        self._current = cached
        return cached
