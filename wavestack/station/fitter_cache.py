"""Fitters for the apertures a station sees: the configured method built in the background.

Building a CSF-QCM fitter costs about a second at station resolution, a refit a few
milliseconds. When the aperture changes, the station must not stall: :class:`FitterCache` starts
the configured build on a worker thread and, until it is ready, hands out a ``qr`` fitter (the
same Zernike modes orthonormalised on the new samples) built at once, flagged as such. A ``qr``
fit is exact for the modes it fits; it differs from the mapped fit in what the coefficients mean
on a non-circular aperture, which is why results on it carry the flag.
"""

from __future__ import annotations

import logging
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

from wavestack.config import FitSettings
from wavestack.pipeline import Aperture, Fitter, build_fitter

logger = logging.getLogger(__name__)

FALLBACK_METHOD = "qr"


@dataclass(frozen=True, eq=False)
class FitterChoice:
    """The fitter to use for one result.

    Attributes
    ----------
    fitter : Fitter
    kind : str
        The method that built it (``csf-qcm``, ``qr``, ``circle``, ``annulus``, ``conformal``).
    fallback : bool
        True when it stands in for the configured method while that one is being built.
    aperture_id : int
        Which aperture (counted from 0 per station run) it was built for.
    """

    fitter: Fitter
    kind: str
    fallback: bool
    aperture_id: int


class FitterCache:
    """Hold the fitter of the current aperture; build the configured one off the result path.

    Parameters
    ----------
    settings : FitSettings
    background : bool
        Build the configured method on a worker thread (station) or synchronously (replay,
        tests that need determinism).
    """

    def __init__(self, settings: FitSettings, *, background: bool = True) -> None:
        self._settings = settings
        self._executor = (
            ThreadPoolExecutor(max_workers=1, thread_name_prefix="fitter-build") if background else None
        )
        self._lock = threading.Lock()
        self._aperture_id = -1
        self._current: FitterChoice | None = None
        self._aperture: Aperture | None = None
        self._built: dict[str, FitterChoice] = {}  # fitters of the current aperture, by method
        self._pending: Future[Fitter] | None = None
        self._pending_started = 0.0
        self.last_build_s: float | None = None

    @property
    def settings(self) -> FitSettings:
        return self._settings

    def _build(self, aperture: Aperture, method: str) -> Fitter:
        s = self._settings
        return build_fitter(aperture, method=method, modes=s.modes, ordering=s.ordering, remove=s.remove,
                            mesh_vertices=s.mesh_vertices, obscuration=s.obscuration,
                            fallback="qr" if method in ("csf-qcm", "conformal") else None)

    def new_aperture(self, aperture: Aperture, *, method: str | None = None) -> FitterChoice:
        """Start using a new aperture; returns the fitter to use at once.

        Parameters
        ----------
        aperture : Aperture
        method : str, optional
            Force this method synchronously (replay reproducing a result that ran on a fallback).
        """
        with self._lock:
            self._aperture_id += 1
            aperture_id = self._aperture_id
            if self._pending is not None:
                self._pending.cancel()  # a build for an aperture already gone; a running one finishes unused
                self._pending = None
        configured = self._settings.method
        if method is not None or self._executor is None or configured == FALLBACK_METHOD:
            kind = method or configured
            tick = time.perf_counter()
            fitter = self._build(aperture, kind)
            built = fitter.diagnostics.method  # a mapped method may have fallen back to qr
            choice = FitterChoice(fitter, built, built != configured, aperture_id)
            self.last_build_s = time.perf_counter() - tick
        else:
            # The configured build starts first, so that it runs on the other core while this
            # thread builds the stand-in (measured: about 0.2 s sooner to the new map).
            with self._lock:
                self._pending_started = time.perf_counter()
                self._pending = self._executor.submit(self._build, aperture, configured)
            choice = FitterChoice(self._build(aperture, FALLBACK_METHOD), FALLBACK_METHOD, True, aperture_id)
        with self._lock:
            self._current = choice
            self._aperture = aperture
            self._built = {choice.kind: choice}
        return choice

    def use_method(self, method: str) -> FitterChoice:
        """Switch the current aperture to a fitter of ``method``, built synchronously once.

        Replay uses it to run each result on the fitter that ran it live (a ``qr`` stand-in, then
        the configured method once its build had finished).
        """
        with self._lock:
            current, aperture = self._current, self._aperture
            cached = self._built.get(method)
        if current is None or aperture is None:
            raise RuntimeError("use_method before any aperture")
        if cached is None:
            fitter = self._build(aperture, method)
            cached = FitterChoice(fitter, fitter.diagnostics.method, fitter.diagnostics.method != self._settings.method,
                                  current.aperture_id)
        with self._lock:
            self._built[method] = cached
            self._current = cached
        return cached

    def current(self) -> FitterChoice | None:
        """The best fitter for the current aperture: the configured one once its build is done."""
        with self._lock:
            pending, current = self._pending, self._current
        if pending is not None and pending.done() and current is not None:
            with self._lock:
                if self._pending is not pending:  # a newer aperture arrived meanwhile
                    return self._current
                self._pending = None
                error = pending.exception()
                if error is not None:
                    logger.warning("building the %s fitter failed (%s); staying on %s",
                                   self._settings.method, error, current.kind)
                    return current
                self.last_build_s = time.perf_counter() - self._pending_started
                fitter = pending.result()
                built = fitter.diagnostics.method
                self._current = FitterChoice(fitter, built, built != self._settings.method, current.aperture_id)
                logger.info("%s fitter ready for aperture %d after %.2f s",
                            self._settings.method, current.aperture_id, self.last_build_s)
                return self._current
        return current

    def wait_for_build(self, timeout_s: float) -> bool:
        """Block until a pending build finishes (tests, replay); True if none is pending after."""
        with self._lock:
            pending = self._pending
        if pending is None:
            return True
        try:
            pending.exception(timeout=timeout_s)
        except TimeoutError:
            return False
        return True

    def close(self) -> None:
        """Stop the worker (a running build is waited for, queued ones dropped); idempotent."""
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)
