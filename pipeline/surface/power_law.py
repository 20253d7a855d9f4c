"""A power law ``PSD(f) = A f^slope`` fitted to a spectrum over a band.

The fit is a weighted least-squares line through ``log PSD`` against ``log f`` over the
spectrum's rings in the band, each ring weighted by the inverse variance of its log: a ring of
one frequency step at ``f`` averages a number of 2-D samples that grows as ``f`` (its
circumference), and the log of a mean of ``N`` periodogram samples scatters with a variance of
about ``1 / N``, so the weight is ``f``. That is the best linear unbiased estimate for rings
spaced linearly; weighting the rings alike gives the few, poorly averaged low rings the same say
as the well averaged high ones and scatters the slope more (on the f^-3 surfaces of the tests,
by about a quarter). ``A`` is the PSD at 1 cycle/mm, in the spectrum's units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["PowerLaw", "fit_power_law"]


@dataclass(frozen=True)
class PowerLaw:
    """``PSD(f) = amplitude * f^slope`` over a band.

    Attributes
    ----------
    amplitude : float
        PSD at f = 1 cycle/mm, in the spectrum's units (nm^2 mm^2 for the azimuthal average).
    slope : float
        Exponent (negative for a surface rougher at long periods).
    band_per_mm : (float, float)
        The band fitted, cycles/mm.
    rings : int
        Spectrum samples in the band.
    """

    amplitude: float
    slope: float
    band_per_mm: tuple[float, float]
    rings: int

    def as_dict(self) -> dict[str, object]:
        """JSON-ready form."""
        return {"amplitude_nm2_mm2": self.amplitude, "slope": self.slope, "band_per_mm": list(self.band_per_mm),
                "rings": self.rings}


def fit_power_law(frequency: NDArray[np.float64], psd: NDArray[np.float64], low: float, high: float) -> PowerLaw:
    """Fit ``A f^slope`` to the positive samples of a spectrum with ``low <= f <= high``.

    Parameters
    ----------
    frequency, psd : ndarray, shape (B,)
        Spectrum samples (frequency > 0): ring means of a 2-D spectrum on equally spaced rings,
        weighted by ``f`` (module notes).
    low, high : float
        The band, in the frequency's units.

    Raises
    ------
    ValueError
        If fewer than three positive samples lie in the band.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.linspace(0.1, 10, 100)
    >>> law = fit_power_law(f, 3.0 * f**-2.5, 0.2, 8.0)
    >>> round(law.amplitude, 9), round(law.slope, 9)
    (3.0, -2.5)
    """
    inside = (frequency >= low) & (frequency <= high) & (psd > 0)
    count = int(np.count_nonzero(inside))
    if count < 3:
        raise ValueError(f"band {low:g}-{high:g} cycles/mm holds {count} spectrum samples; expected at least 3 "
                         "(a wider band, or a larger measured area)")
    x, y = np.log10(frequency[inside]), np.log10(psd[inside])
    slope, intercept = np.polyfit(x, y, 1, w=np.sqrt(frequency[inside]))  # residuals x w: weights f (module notes)
    return PowerLaw(amplitude=float(10.0**intercept), slope=float(slope), band_per_mm=(float(low), float(high)),
                    rings=count)
