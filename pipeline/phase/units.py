"""Unit conversions of measured phase: radians, waves, nanometres, surface height.

Sign convention (project-wide): the phase ``phi`` is in radians and a positive ``phi`` is a
positive wavefront. Every conversion here is a multiplication by a positive or a
user-chosen factor, so the sign is carried through unchanged:

* waves = phi / (2 pi);
* wavefront in nm = waves * wavelength_nm;
* surface = wavefront * factor.

The surface factor depends on the test geometry:

* ``0.5``: reflection at normal incidence (double pass; the default). A surface height
  error ``h`` changes the reflected optical path by ``2 h``.
* ``1 / (2 cos theta)``: reflection at angle of incidence ``theta`` (the path changes by
  ``2 h cos theta``), e.g. a grazing-incidence or Ritchey-Common style setup.
* ``1.0``: transmission, single pass, when the quantity of interest is the transmitted
  wavefront itself.
* ``1 / (n - 1)``: thickness variation of a window of refractive index ``n`` in single pass
  transmission (``1 / (2 (n - 1))`` in double pass).
* a negative factor, to report the surface with the opposite sign convention (e.g. height
  measured into the material).

Values may be NaN (pixels outside an aperture); NaN propagates.

This module is the one place for these conversions. A wavefront in waves becomes nanometres
with :func:`waves_to_nm` (``waves * wavelength_nm``), a phase map in radians becomes waves with
:func:`phase_to_waves` and nanometres with :func:`phase_to_nm`, and a wavefront becomes surface
height with :func:`wavefront_to_surface`; :class:`WavefrontUnits` holds the wavelength and the
surface factor of one setup. All are on the faces ``wavestack.pipeline.phase`` and
``wavestack.pipeline``.

References
----------
.. [1] D. Malacara (ed.), *Optical Shop Testing*, 3rd ed. (Wiley, 2007), ch. 1-2 (surface
   versus wavefront in reflection and transmission tests).
.. [2] ISO 10110-5:2015, Optics and photonics - Preparation of drawings for optical elements
   and systems - Part 5: Surface form tolerances (surface form stated as half the double
   pass wavefront deviation at normal incidence).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import is_finite_real, real_at_least, require_real_dtype

__all__ = [
    "WavefrontUnits",
    "nm_to_phase",
    "nm_to_waves",
    "phase_to_nm",
    "phase_to_waves",
    "surface_to_wavefront",
    "wavefront_to_surface",
    "waves_to_nm",
    "waves_to_phase",
]

_TWO_PI = 2.0 * math.pi


# ----------------------------------------------------------------------------- functions


def phase_to_waves(phase: ArrayLike) -> float | NDArray[np.float64]:
    """Convert phase in radians to waves.

    Parameters
    ----------
    phase : float or array_like
        Phase in radians, any shape; NaN propagates.

    Returns
    -------
    float or NDArray[np.float64]
        ``phase / (2 pi)`` in waves: a float for a scalar input, else an array of the same
        shape.

    Raises
    ------
    ValueError
        If ``phase`` is not real numeric (booleans, complex numbers and strings are refused).

    References
    ----------
    .. [1] D. Malacara (ed.), *Optical Shop Testing*, 3rd ed. (Wiley, 2007), ch. 1.

    Examples
    --------
    >>> phase_to_waves(3.141592653589793)
    0.5
    """
    return _scaled(phase, "phase", 1.0 / _TWO_PI)


def waves_to_phase(waves: ArrayLike) -> float | NDArray[np.float64]:
    """Convert waves to phase in radians (inverse of :func:`phase_to_waves`).

    Parameters
    ----------
    waves : float or array_like
        Optical path in waves, any shape; NaN propagates.

    Returns
    -------
    float or NDArray[np.float64]
        ``2 pi waves`` in radians, float for a scalar, else an array of the same shape.

    Raises
    ------
    ValueError
        If ``waves`` is not real numeric.

    References
    ----------
    .. [1] D. Malacara (ed.), *Optical Shop Testing*, 3rd ed. (Wiley, 2007), ch. 1.
    """
    return _scaled(waves, "waves", _TWO_PI)


def waves_to_nm(waves: ArrayLike, wavelength_nm: float) -> float | NDArray[np.float64]:
    """Convert waves to nanometres of optical path.

    Parameters
    ----------
    waves : float or array_like
        Optical path in waves, any shape; NaN propagates.
    wavelength_nm : float
        Test wavelength in nm (e.g. 632.8 for HeNe); finite and > 0.

    Returns
    -------
    float or NDArray[np.float64]
        ``waves * wavelength_nm`` in nm, float for a scalar, else an array of the same shape.

    Raises
    ------
    ValueError
        If ``waves`` is not real numeric or ``wavelength_nm`` is not a finite number > 0.

    References
    ----------
    .. [1] D. Malacara (ed.), *Optical Shop Testing*, 3rd ed. (Wiley, 2007), ch. 1.

    Examples
    --------
    >>> waves_to_nm(0.5, 632.8)
    316.4
    """
    return _scaled(waves, "waves", _validated_wavelength(wavelength_nm))


def nm_to_waves(nm: ArrayLike, wavelength_nm: float) -> float | NDArray[np.float64]:
    """Convert nanometres of optical path to waves (inverse of :func:`waves_to_nm`).

    Parameters
    ----------
    nm : float or array_like
        Optical path in nm, any shape; NaN propagates.
    wavelength_nm : float
        Test wavelength in nm; finite and > 0.

    Returns
    -------
    float or NDArray[np.float64]
        ``nm / wavelength_nm`` in waves, float for a scalar, else an array of the same shape.

    Raises
    ------
    ValueError
        If ``nm`` is not real numeric or ``wavelength_nm`` is not a finite number > 0.

    References
    ----------
    .. [1] D. Malacara (ed.), *Optical Shop Testing*, 3rd ed. (Wiley, 2007), ch. 1.
    """
    return _scaled(nm, "nm", 1.0 / _validated_wavelength(wavelength_nm))


def phase_to_nm(phase: ArrayLike, wavelength_nm: float) -> float | NDArray[np.float64]:
    """Convert phase in radians to nanometres of wavefront (optical path).

    Parameters
    ----------
    phase : float or array_like
        Phase in radians, any shape; NaN propagates.
    wavelength_nm : float
        Test wavelength in nm; finite and > 0.

    Returns
    -------
    float or NDArray[np.float64]
        ``phase * wavelength_nm / (2 pi)`` in nm, float for a scalar, else an array of the
        same shape.

    Raises
    ------
    ValueError
        If ``phase`` is not real numeric or ``wavelength_nm`` is not a finite number > 0.

    References
    ----------
    .. [1] D. Malacara (ed.), *Optical Shop Testing*, 3rd ed. (Wiley, 2007), ch. 1.
    """
    return _scaled(phase, "phase", _validated_wavelength(wavelength_nm) / _TWO_PI)


def nm_to_phase(nm: ArrayLike, wavelength_nm: float) -> float | NDArray[np.float64]:
    """Convert nanometres of wavefront to phase in radians (inverse of :func:`phase_to_nm`).

    Parameters
    ----------
    nm : float or array_like
        Wavefront (optical path) in nm, any shape; NaN propagates.
    wavelength_nm : float
        Test wavelength in nm; finite and > 0.

    Returns
    -------
    float or NDArray[np.float64]
        ``2 pi nm / wavelength_nm`` in radians, float for a scalar, else an array of the
        same shape.

    Raises
    ------
    ValueError
        If ``nm`` is not real numeric or ``wavelength_nm`` is not a finite number > 0.

    References
    ----------
    .. [1] D. Malacara (ed.), *Optical Shop Testing*, 3rd ed. (Wiley, 2007), ch. 1.
    """
    return _scaled(nm, "nm", _TWO_PI / _validated_wavelength(wavelength_nm))


def wavefront_to_surface(wavefront: ArrayLike, factor: float = 0.5) -> float | NDArray[np.float64]:
    """Convert a wavefront to a surface (or thickness) map: ``surface = wavefront * factor``.

    Parameters
    ----------
    wavefront : float or array_like
        Wavefront in any length unit (waves, nm, ...), any shape; NaN propagates. The
        surface comes out in the same unit.
    factor : float, optional
        Surface per unit of wavefront; finite and non-zero. ``0.5`` (default) for reflection
        at normal incidence (double pass), ``1 / (2 cos theta)`` at angle of incidence
        ``theta``, ``1.0`` for a transmitted wavefront in single pass, ``1 / (n - 1)`` for
        the thickness of a window of index ``n`` in single pass; negative to flip the sign
        convention (see the module notes).

    Returns
    -------
    float or NDArray[np.float64]
        ``wavefront * factor``, float for a scalar, else an array of the same shape.

    Raises
    ------
    ValueError
        If ``wavefront`` is not real numeric or ``factor`` is not a finite non-zero number.

    References
    ----------
    .. [1] D. Malacara (ed.), *Optical Shop Testing*, 3rd ed. (Wiley, 2007), ch. 1-2.
    """
    return _scaled(wavefront, "wavefront", _validated_factor(factor))


def surface_to_wavefront(surface: ArrayLike, factor: float = 0.5) -> float | NDArray[np.float64]:
    """Convert a surface map back to a wavefront (inverse of :func:`wavefront_to_surface`).

    Parameters
    ----------
    surface : float or array_like
        Surface (or thickness) in any length unit, any shape; NaN propagates.
    factor : float, optional
        The factor of :func:`wavefront_to_surface` (default 0.5); finite and non-zero.

    Returns
    -------
    float or NDArray[np.float64]
        ``surface / factor``, float for a scalar, else an array of the same shape.

    Raises
    ------
    ValueError
        If ``surface`` is not real numeric or ``factor`` is not a finite non-zero number.

    References
    ----------
    .. [1] D. Malacara (ed.), *Optical Shop Testing*, 3rd ed. (Wiley, 2007), ch. 1-2.
    """
    return _scaled(surface, "surface", 1.0 / _validated_factor(factor))


# ----------------------------------------------------------------------------- dataclass


@dataclass(frozen=True)
class WavefrontUnits:
    """Conversions of measured phase for one test setup.

    Attributes
    ----------
    wavelength_nm : float
        Test wavelength in nm (e.g. 632.8); finite and > 0.
    surface_factor : float
        Surface per unit of wavefront (default 0.5, reflection at normal incidence); finite
        and non-zero. See :func:`wavefront_to_surface` for other geometries.

    Raises
    ------
    ValueError
        On construction, if ``wavelength_nm`` is not a finite number > 0 or
        ``surface_factor`` is not a finite non-zero number (booleans are refused).

    Examples
    --------
    >>> units = WavefrontUnits(wavelength_nm=632.8)
    >>> round(units.to_nm(3.141592653589793), 6)
    316.4
    >>> round(units.surface_nm(3.141592653589793), 6)
    158.2
    """

    wavelength_nm: float
    surface_factor: float = 0.5

    def __post_init__(self) -> None:
        # Validate and normalise to plain floats (frozen: set through object.__setattr__).
        object.__setattr__(self, "wavelength_nm", _validated_wavelength(self.wavelength_nm))
        factor = _validated_factor(self.surface_factor, "surface_factor")
        object.__setattr__(self, "surface_factor", factor)

    def to_waves(self, phase: ArrayLike) -> float | NDArray[np.float64]:
        """Phase in radians to waves (``phase / 2 pi``); float for a scalar input.

        Raises
        ------
        ValueError
            If ``phase`` is not real numeric.
        """
        return phase_to_waves(phase)

    def to_nm(self, phase: ArrayLike) -> float | NDArray[np.float64]:
        """Phase in radians to wavefront in nm (``phase * wavelength_nm / 2 pi``).

        Raises
        ------
        ValueError
            If ``phase`` is not real numeric.
        """
        return phase_to_nm(phase, self.wavelength_nm)

    def surface_nm(self, phase: ArrayLike) -> float | NDArray[np.float64]:
        """Phase in radians to surface in nm (``to_nm(phase) * surface_factor``).

        Raises
        ------
        ValueError
            If ``phase`` is not real numeric.
        """
        return _scaled(phase, "phase", self.wavelength_nm / _TWO_PI * self.surface_factor)

    def phase_from_nm(self, wavefront_nm: ArrayLike) -> float | NDArray[np.float64]:
        """Wavefront in nm back to phase in radians (inverse of :meth:`to_nm`).

        Raises
        ------
        ValueError
            If ``wavefront_nm`` is not real numeric.
        """
        return nm_to_phase(wavefront_nm, self.wavelength_nm)

    def phase_from_surface_nm(self, surface_nm: ArrayLike) -> float | NDArray[np.float64]:
        """Surface in nm back to phase in radians (inverse of :meth:`surface_nm`).

        Raises
        ------
        ValueError
            If ``surface_nm`` is not real numeric.
        """
        scale = _TWO_PI / (self.wavelength_nm * self.surface_factor)
        return _scaled(surface_nm, "surface_nm", scale)


# ----------------------------------------------------------------------------- helpers


def _scaled(value: ArrayLike, name: str, scale: float) -> float | NDArray[np.float64]:
    """``value * scale`` as float64: a float for scalar input, else an array."""
    array = np.asarray(value)
    require_real_dtype(array, name)
    result = np.multiply(array, scale, dtype=np.float64)
    if result.ndim == 0:
        return float(result)
    return result


def _validated_wavelength(value: float) -> float:
    return real_at_least(value, "wavelength_nm", 0.0, strict=True, unit="nm")


def _validated_factor(value: float, name: str = "factor") -> float:
    if not is_finite_real(value) or value == 0.0:
        raise ValueError(f"{name} must be a finite non-zero number, got {value!r}")
    return float(value)
