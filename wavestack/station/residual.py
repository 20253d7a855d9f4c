"""The peak-to-valley of a fit's residual on the station's fit grid, at the cost of about one refit.

The residual of a fit is the map minus everything the fit took out of it: the fitted basis
terms and the physical terms removed before the fit. Its RMS comes with every fit (from the
normal equations); its peak-to-valley needs the residual at every sample. The fitter computes it
on request (``Fitter.fit(..., residual=True)``), but in float64 terms against the float32
operator, so numpy copies the whole operator to float64 on every call, and it also builds the
full-size residual map. On the default station (1024 x 1024 decimated by 2: 142,536 samples x
(36 + 3) columns) that measured 6.4-6.6 ms per result, against 0.9-1.0 ms for the fit itself
(median of 60, both fitters, qr and csf-qcm, on a quiet moment of the 2-core test machine; under
load all of these grow four- to eightfold alike).

:class:`ResidualPeakToValley` evaluates the same residual, ``samples - [H | E] [x_basis; x_removed]``,
in one float32 pass over the fitter's own operator (the pass a refit makes), from the fit's
coefficients mapped back to the orthonormal basis (``from_coefficients``, the map the fitter's
``surface`` uses) and the removed physical terms mapped back through ``removal_transform``. No
full-size map is made. It costs about one more refit: 0.8-1.0 ms per result on the default
station, measured as above; it agrees with the fitter's ``residual_pv`` to 1e-7 waves (float32
terms on waves-sized maps).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline import FitResult, Fitter


class ResidualPeakToValley:
    """Residual peak-to-valley of fits, keeping the arrays of the last fitter used.

    Examples
    --------
    >>> from wavestack.pipeline import build_fitter
    >>> yy, xx = np.mgrid[-20:21, -20:21] / 20.0
    >>> mask = xx ** 2 + yy ** 2 <= 1.0
    >>> fitter = build_fitter(mask, method="qr", modes=6, remove="ptt")
    >>> waves = 0.3 * (xx ** 2 + yy ** 2) + 0.01 * np.sin(40.0 * xx)
    >>> fit = fitter.fit(waves)
    >>> pv = ResidualPeakToValley()(fitter, waves, fit)
    >>> bool(abs(pv - fitter.fit(waves, residual=True).residual_pv) < 1e-5)
    True
    """

    def __init__(self) -> None:
        self._fitter: Fitter | None = None
        self._flat_index: NDArray[np.intp] = np.empty(0, np.intp)
        self._from_coefficients: NDArray[np.float64] = np.empty((0, 0))
        self._to_removed: NDArray[np.float64] | None = None

    def __call__(self, fitter: Fitter, waves: NDArray[np.floating], fit: FitResult) -> float:
        """Peak-to-valley of ``waves`` minus what ``fit`` took out, over the fitted samples.

        Parameters
        ----------
        fitter : Fitter
            The fitter that made ``fit``.
        waves : ndarray, shape ``fitter.aperture.shape``
            The map that was fitted, waves; NaN samples (omitted by the fit) are left out here too.
        fit : FitResult

        Returns
        -------
        float
            Waves; NaN when no sample is finite.
        """
        if fitter is not self._fitter:
            self._adopt(fitter)
        operator = fitter.operator
        terms = [self._from_coefficients @ np.asarray(fit.coefficients, dtype=np.float64)]
        if self._to_removed is not None:
            removed = fit.removed
            assert removed is not None  # a fitter that removes physical terms reports them
            physical = [removed.piston, removed.tilt_x, removed.tilt_y]
            physical += [] if removed.power is None else [removed.power]
            terms.append(self._to_removed @ np.asarray(physical, dtype=np.float64))
        fitted = operator @ np.concatenate(terms).astype(operator.dtype)
        residual = np.take(np.asarray(waves).reshape(-1), self._flat_index) - fitted
        finite = residual[np.isfinite(residual)]
        return float(finite.max() - finite.min()) if finite.size else float("nan")

    def _adopt(self, fitter: Fitter) -> None:
        state = fitter.export_state()
        self._flat_index = np.asarray(state["flat_index"], dtype=np.intp)
        self._from_coefficients = np.asarray(state["from_coefficients"], dtype=np.float64)
        removal = state["removal_transform"]
        self._to_removed = None if fitter.removal is None or removal is None else np.linalg.inv(
            np.asarray(removal, dtype=np.float64))
        self._fitter = fitter
