"""The station's fitter source: the configured method built in the background.

Building a CSF-QCM fitter costs about a second at station resolution, a refit a few
milliseconds. When the aperture changes, the station must not stall: :class:`FitterCache` starts
the configured build on a worker thread and, until it is ready, hands out a ``qr`` fitter (the
same Zernike modes orthonormalised on the new samples) built at once, flagged as such. A ``qr``
fit is exact for the modes it fits; it differs from the mapped fit in what the coefficients mean
on a non-circular aperture, which is why results on it carry the flag.

It is a :class:`~wavestack.pipeline.FitterSource`: the processor (in ``pipeline``) asks it for
fitters and knows nothing of its thread. Every fitter is built by
:func:`~wavestack.pipeline.instrument.build_configured`, as ``analyze`` and ``replay``'s synchronous
source builds it, so a fitter does not depend on who built it.
"""

from __future__ import annotations

import logging
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline import Aperture, Fitter
from wavestack.pipeline.instrument import FALLBACK_METHOD, FitSettings, FitterChoice, build_configured, choice_of

logger = logging.getLogger(__name__)

__all__ = ["FALLBACK_METHOD", "FitterCache", "FitterChoice"]


class FitterCache:
    """Hold the fitter of the current aperture; build the configured one off the result path.

    Parameters
    ----------
    settings : FitSettings
    """

    def __init__(self, settings: FitSettings) -> None:
        self._settings = settings
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="fitter-build")
        self._lock = threading.Lock()
        self._aperture_id = -1
        self._current: FitterChoice | None = None
        self._aperture: Aperture | None = None
        self._fit_mask: NDArray[np.bool_] | None = None
        self._built: dict[str, FitterChoice] = {}  # fitters of the current aperture, by method
        self._pending: Future[Fitter] | None = None
        self._pending_started = 0.0
        self.last_build_s: float | None = None

    @property
    def settings(self) -> FitSettings:
        return self._settings

    def new_aperture(self, aperture: Aperture, *, fit_mask: NDArray[np.bool_] | None = None,
                     method: str | None = None) -> FitterChoice:
        """Start using a new aperture; returns the fitter to use at once.

        Parameters
        ----------
        aperture : Aperture
        fit_mask : ndarray of bool, optional
            The pixels to fit, when not the whole aperture.
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
        if method is not None or configured == FALLBACK_METHOD:
            tick = time.perf_counter()
            choice = choice_of(build_configured(aperture, self._settings, method or configured, fit_mask),
                               configured, aperture_id)
            self.last_build_s = time.perf_counter() - tick
        else:
            # The configured build starts first, so that it runs on the other core while this
            # thread builds the stand-in (measured: about 0.2 s sooner to the new map).
            with self._lock:
                self._pending_started = time.perf_counter()
                self._pending = self._executor.submit(build_configured, aperture, self._settings, configured,
                                                      fit_mask)
            stand_in = build_configured(aperture, self._settings, FALLBACK_METHOD, fit_mask)
            choice = FitterChoice(stand_in, FALLBACK_METHOD, True, aperture_id)
        with self._lock:
            self._current = choice
            self._aperture, self._fit_mask = aperture, fit_mask
            self._built = {choice.kind: choice}
        return choice

    def use_method(self, method: str) -> FitterChoice:
        """Switch the current aperture to a fitter of ``method``, built synchronously once."""
        with self._lock:
            current, aperture, fit_mask = self._current, self._aperture, self._fit_mask
            cached = self._built.get(method)
        if current is None or aperture is None:
            raise RuntimeError("use_method before any aperture")
        if cached is None:
            cached = choice_of(build_configured(aperture, self._settings, method, fit_mask), self._settings.method,
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
                self._current = choice_of(pending.result(), self._settings.method, current.aperture_id)
                self._built[self._current.kind] = self._current
                logger.info("%s fitter ready for aperture %d after %.2f s",
                            self._settings.method, current.aperture_id, self.last_build_s)
                return self._current
        return current

    def wait_for_build(self, timeout_s: float) -> bool:
        """Block until a pending build finishes (tests); True if none is pending after."""
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
        self._executor.shutdown(wait=True, cancel_futures=True)
