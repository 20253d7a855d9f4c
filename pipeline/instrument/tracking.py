"""The aperture a stream of sets is measured on: watched every set, detected on a change, confirmed, adopted.

Per set, the cheap :class:`~wavestack.pipeline.ApertureWatch` compares the aperture signal (the
modulation, or a carrier frame's fringe energy) with the aperture in use; only when it reports a
change does the full detection run (:func:`~wavestack.pipeline.choose_aperture`: detected or the
circle fitted to its edge), and only when the next set confirms a change is it adopted
(:mod:`~.confirmation`'s table). A user's mask is adopted on the first set and never watched.

Adopting an aperture fixes what the fit grid (every ``fit_decimation``-th pixel) sees of it: its
pixels, those the fitter is built on (the aperture less its pixels of low modulation in the
adopting set: a dust dropout the detection filled, a speck the closing took in; and less the rim
band the phase method cannot measure, ``rim_px`` wide; both counted in every result), their
connected components (for the quality mask), the PVr analyzer and, for a null test, the null
wavefront on the pupil. The fit's pupil is still the whole aperture's (its edge).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from ..aperture import (
    Aperture,
    ApertureWatch,
    DetectionSettings,
    EdgeCircle,
    choose_aperture,
    compare_apertures,
)
from ..surface import RobustPVAnalyzer
from ..zernike import null_wavefront_waves
from .confirmation import ApertureAction, ApertureEvent, AperturePhase, ApertureState, Detection, confirm
from .fitter_source import FitterSource
from .quality import LOW_MODULATION, OUTSIDE, RIM
from .settings import ConicNull, InterferometerSettings
from .statistics import pvr_analyzer

__all__ = ["AdoptedAperture", "ApertureConfirming", "ApertureKeeper", "null_waves"]


class ApertureConfirming(ValueError):
    """The set shows an aperture unlike the one in use: it waits for the next set to confirm it."""

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class AdoptedAperture:
    """The aperture in use, as the fit grid sees it.

    Attributes
    ----------
    aperture : Aperture
        Full resolution.
    choice : str
        ``detected``, ``circle`` or ``mask``.
    edge : EdgeCircle or None
    marks : ndarray of uint8
        The fit grid's marks fixed at adoption: :data:`~.quality.OUTSIDE` outside the aperture, 0
        on the pixels the fitter is built on, :data:`~.quality.LOW_MODULATION` or
        :data:`~.quality.RIM` on those left out (module notes).
    components : (ndarray of int32, int)
        Labels of the connected components of the fitted pixels (4-connectivity) and their count + 1.
    pvr : RobustPVAnalyzer or None
        Evans' PVr on the fitted pixels (None where the 36 terms cannot be fitted there).
    null_waves : ndarray or None
        The null test's wavefront on the fit grid, waves.
    """

    aperture: Aperture
    choice: str
    edge: EdgeCircle | None
    marks: NDArray[np.uint8]
    components: tuple[NDArray[np.int32], int]
    pvr: RobustPVAnalyzer | None
    null_waves: NDArray[np.float64] | None

    @property
    def fitted(self) -> NDArray[np.bool_]:
        """The pixels the fitter is built on (the fit grid)."""
        return self.marks == 0


class ApertureKeeper:
    """Keeps, or changes to, the aperture each set shows (module notes).

    Parameters
    ----------
    settings : InterferometerSettings
    fitters : FitterSource
        Asked for the fitter of each adopted aperture.
    mask : ndarray of bool, optional
        The user's aperture (full resolution): used as it is, never detected.
    """

    def __init__(self, settings: InterferometerSettings, fitters: FitterSource,
                 mask: NDArray[np.bool_] | None = None) -> None:
        self._settings = settings
        self._fitters = fitters
        self._mask = None if mask is None else np.asarray(mask, dtype=bool)
        self._state = ApertureState()
        self.adopted: AdoptedAperture | None = None

    def update(self, signal: NDArray, modulation: NDArray, detection: DetectionSettings, fitter_method: str | None,
               *, rim_px: int = 0, before_detection: Callable[[], None] | None = None
               ) -> tuple[bool, ValueError | None]:
        """Watch, detect, confirm: whether this set starts a new aperture, and why it is invalid (or None).

        ``rim_px``: the width of the band along the edge the phase method cannot measure (full
        resolution), left out of the fit when an aperture is adopted. ``before_detection`` runs
        before a full detection and may refuse the set (a ValueError, e.g. frames without
        fringes): the aperture is then forgotten and the error returned.

        Raises
        ------
        ValueError
            A user's mask of another shape than the frames.
        """
        state = self._state
        if self._mask is not None and self._mask.shape != np.shape(signal):
            raise ValueError(f"aperture mask has shape {self._mask.shape}; expected the frames' shape "
                             f"{np.shape(signal)}")
        if self._mask is not None and state.current is not None:
            self._state, _ = confirm(state, ApertureEvent.QUIET)
            return False, None
        if state.watch is not None and not state.watch.check(signal).changed:
            self._state, _ = confirm(state, ApertureEvent.QUIET)
            return False, None
        try:
            if before_detection is not None:
                before_detection()
            return self._detect(signal, modulation, detection, fitter_method, rim_px)
        except ValueError as error:  # empty or unsupported, no fringes, no circle, a basis the aperture cannot carry
            self.forget()
            return False, error

    def forget(self) -> None:
        """Drop the aperture (a failed detection): the next set starts afresh."""
        self._state, _ = confirm(self._state, ApertureEvent.FAILED)
        self.adopted = None

    def _detect(self, signal: NDArray, modulation: NDArray, detection: DetectionSettings,
                fitter_method: str | None, rim_px: int) -> tuple[bool, ValueError | None]:
        """The full detection, classified and confirmed; a new fitter when the aperture is adopted."""
        state = self._state
        chosen = choose_aperture(signal, self._settings.aperture if self._mask is None else self._mask, detection)
        watch = None
        if chosen.detected is not None:
            detected = chosen.detected
            watch = ApertureWatch(detected.aperture.mask, detected.threshold, factor=self._settings.watch_block_px)
        event, difference = self._classify(state, chosen.aperture)
        self._state, action = confirm(state, event, Detection(chosen.aperture, watch))
        if action is ApertureAction.CONFIRMING:
            return False, ApertureConfirming(f"aperture changed ({difference}); confirming on the next set")
        if action is ApertureAction.KEEP:
            return False, None
        if state.current is not None:
            logger.info("aperture changed (%s): %s", difference, chosen.aperture.describe())
        self.adopted = self._adopt(chosen.aperture, chosen.choice, chosen.edge, modulation, fitter_method, rim_px)
        return True, None

    def _adopt(self, aperture: Aperture, choice: str, edge: EdgeCircle | None, modulation: NDArray,
               fitter_method: str | None, rim_px: int) -> AdoptedAperture:
        s = self._settings
        step = s.fit_decimation
        grid = aperture if step == 1 else Aperture.from_mask(aperture.mask[::step, ::step])
        marks = _marks(aperture, grid, np.asarray(modulation)[::step, ::step], s.quality.min_modulation, rim_px, step)
        fitted = marks == 0
        fit_mask = None if np.array_equal(fitted, grid.mask) else fitted
        self._fitters.new_aperture(grid, fit_mask=fit_mask, method=fitter_method)
        count, labels = cv2.connectedComponents(fitted.view(np.uint8), connectivity=4, ltype=cv2.CV_32S)
        null = None if s.null is None else null_waves(grid, s.null)
        return AdoptedAperture(aperture, choice, edge, marks, (labels, count),
                               pvr_analyzer(fitted, s.fit.remove, s.fit.dtype), null)

    def _classify(self, state: ApertureState, aperture: Aperture) -> tuple[ApertureEvent, str | None]:
        """What a full detection shows against the aperture in use and the pending one."""
        if state.current is None:
            return ApertureEvent.NEW, None
        difference = self._difference(state.current, aperture)
        if difference is None:
            return ApertureEvent.SAME, None
        if state.phase is AperturePhase.PENDING and state.pending is not None \
                and self._difference(state.pending, aperture) is None:
            return ApertureEvent.AS_PENDING, difference
        return ApertureEvent.NEW, difference

    def _difference(self, reference: Aperture, aperture: Aperture) -> str | None:
        """Why two apertures are not the same one (None when they are)."""
        change = compare_apertures(reference, aperture, self._settings.iou_threshold)
        return change.reason if change.changed else None


def null_waves(aperture: Aperture, null: ConicNull) -> NDArray[np.float64]:
    """A null test's wavefront over an aperture (its enclosing circle the mirror's edge), waves, NaN outside."""
    cx, cy, radius = aperture.enclosing_circle()
    rows, cols = np.indices(aperture.mask.shape)
    rho = np.hypot(cols - cx, rows - cy) / radius
    return np.where(aperture.mask, null_wavefront_waves(np.minimum(rho, 1.0), null.test, null.conic), np.nan)


def _marks(aperture: Aperture, grid: Aperture, modulation: NDArray, fraction: float, rim_px: int,
           step: int) -> NDArray[np.uint8]:
    """The fit grid's marks at adoption: outside, fitted (0), low modulation, rim (module notes)."""
    inside = grid.mask
    marks = np.where(inside, 0, OUTSIDE).astype(np.uint8)
    if rim_px > 0:
        size = 2 * int(rim_px) + 1
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
        core = cv2.erode(aperture.mask.view(np.uint8), kernel).astype(bool)[::step, ::step]
        marks[inside & ~core] = RIM
    if fraction > 0:
        level = fraction * float(np.mean(modulation[inside]))
        marks[(marks == 0) & (modulation < level)] = LOW_MODULATION
    return marks
