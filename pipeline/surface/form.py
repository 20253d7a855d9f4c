"""ISO 14999-4 form figures of a surface on any measured area: SAG, IRR, RSI, RMSt, RMSi, RMSa.

The definitions (as the public summaries of ISO 14999-4 and ISO 10110-5 agree; kept here, in one
place, so that they can be corrected against the full standard):

* the deviation is the measured surface less piston and tilt (positioning, not the part);
* the best-fit sphere is the least-squares paraboloid of revolution ``c0 + c1 x + c2 y + c3 rho^2``
  about the test area's axis (the centre of its enclosing circle): at interferometric
  departures the sphere and its paraxial paraboloid differ by far less than a nanometre;
* **SAG** (sagitta error, "power") is the sagitta of the best-fit sphere against the nominal
  across the test area: ``c3`` at the test area's radius ``rho = 1``, signed (positive: the
  surface rises toward the edge). For a non-circular test area the radius is that of the
  enclosing circle;
* **IRR** is the peak-to-valley of the deviation from the best-fit sphere (its piston and tilt
  removed with it);
* **RSI** is the peak-to-valley of the rotationally symmetric part of that irregularity about
  the same axis (:mod:`.radial`: a radial profile fitted jointly with the asymmetric terms, so
  an incomplete ring does not lend its asymmetric content to it);
* **RMSt** is the RMS of the deviation, **RMSi** the RMS of the irregularity, **RMSa** the RMS
  of the irregularity less its rotationally symmetric part.

Every RMS is about the mean; every figure is taken over the measured pixels only, in the
surface's units (nm). The sphere is the one least-squares fit of piston, tilt and power of
:func:`~wavestack.pipeline.fit.remove_physical_terms` (its basis), factorised once per area.

References
----------
.. [1] ISO 10110-5:2015, Optics and photonics - Preparation of drawings for optical elements and
   systems - Part 5: Surface form tolerances.
.. [2] ISO 14999-4:2015, Optics and photonics - Interferometric measurement of optical elements
   and optical systems - Part 4: Interpretation and evaluation of tolerances specified in ISO 10110.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..fit import physical_term_basis
from .area import MeasuredArea
from .fringes import fringe_nm
from .radial import MAX_CONDITION, RadialModel

__all__ = ["FormAnalyzer", "FormFigures"]


@dataclass(frozen=True)
class FormFigures:
    """The ISO 14999-4 form figures of one surface, nm of surface height.

    Attributes
    ----------
    sag_nm : float
        Sagitta error of the best-fit sphere across the test area, signed.
    irr_nm, rsi_nm : float
        Peak-to-valley of the irregularity and of its rotationally symmetric part.
    rmst_nm, rmsi_nm, rmsa_nm : float
        RMS of the deviation, of the irregularity, and of the irregularity less its rotationally
        symmetric part.
    pv_nm : float
        Peak-to-valley of the deviation (piston and tilt removed).
    """

    sag_nm: float
    irr_nm: float
    rsi_nm: float
    rmst_nm: float
    rmsi_nm: float
    rmsa_nm: float
    pv_nm: float

    def by_quantity(self) -> dict[str, float]:
        """The six ISO quantities by name (``SAG`` ... ``RMSa``), nm; SAG signed."""
        return {"SAG": self.sag_nm, "IRR": self.irr_nm, "RSI": self.rsi_nm, "RMSt": self.rmst_nm,
                "RMSi": self.rmsi_nm, "RMSa": self.rmsa_nm}

    def as_dict(self, wavelength_nm: float) -> dict[str, object]:
        """JSON-ready: each quantity in nm, in fringes and in waves at ``wavelength_nm``."""
        values = {**self.by_quantity(), "PV": self.pv_nm}
        return {"wavelength_nm": wavelength_nm,
                "nm": values,
                "fringes": {k: v / fringe_nm(wavelength_nm) for k, v in values.items()},
                "waves": {k: v / wavelength_nm for k, v in values.items()}}


class FormAnalyzer:
    """The form figures of surfaces measured on one area: sphere and radial model factorised once.

    Parameters
    ----------
    area : MeasuredArea
    radial_intervals : int
        Knot intervals of the rotationally symmetric profile (:class:`.radial.RadialModel`).
    asymmetric_order : int
        Highest radial order of the asymmetric terms fitted with it (lowered where the
        measured area cannot tell them from a radial profile: :mod:`.radial`).
    max_condition : float
        The radial model's bound on its condition number.

    Attributes
    ----------
    asymmetric_order : int
        The order the radial model uses on this area.

    Raises
    ------
    ValueError
        If the area has too few pixels to determine the model.

    Examples
    --------
    A sphere of 100 nm sagitta plus 20 nm of trefoil on a disk: SAG is the sphere's, RSI zero.

    >>> import numpy as np
    >>> from wavestack.pipeline.surface import measured_area
    >>> rows, cols = np.mgrid[:65, :65]
    >>> x, y = (cols - 32) / 32, (32 - rows) / 32
    >>> disk = x**2 + y**2 <= 1
    >>> surface = 100 * (x**2 + y**2) + 20 * (x**3 - 3 * x * y**2)
    >>> form = FormAnalyzer(measured_area(disk)).figures(surface)
    >>> round(form.sag_nm, 6), round(form.rsi_nm, 6), round(form.irr_nm)
    (100.0, 0.0, 40)
    """

    def __init__(self, area: MeasuredArea, *, radial_intervals: int = 32, asymmetric_order: int = 6,
                 max_condition: float = MAX_CONDITION) -> None:
        x, y = area.coordinates()
        needed = 4 * (radial_intervals + 3 + asymmetric_order * (asymmetric_order + 3) // 2)
        if area.pixels < needed:
            raise ValueError(f"valid: {area.pixels} measured pixels cannot determine the form figures; expected "
                             f"at least {needed} (fewer radial intervals or a lower asymmetric order need fewer)")
        self.area = area
        q, self._sphere_r = np.linalg.qr(physical_term_basis(x, y, "pttp"))
        self._sphere_qt = np.ascontiguousarray(q.T)  # (4, N): one pass over the pixels per product
        self._radial = RadialModel(x, y, intervals=radial_intervals, asymmetric_order=asymmetric_order,
                                   max_condition=max_condition)
        self.asymmetric_order = self._radial.asymmetric_order

    def figures(self, surface_nm: ArrayLike) -> FormFigures:
        """The form figures of a surface.

        Parameters
        ----------
        surface_nm : array_like, shape (rows, cols)
            Surface height in nm (finite on every measured pixel; other pixels are ignored).

        Returns
        -------
        FormFigures

        Raises
        ------
        ValueError
            If the map's shape differs from the area's or a measured pixel is not finite.
        """
        values = self.area.values(surface_nm)
        deviation, irregularity, power = self.deviation_parts(values)
        symmetric = self._radial.symmetric_part(irregularity)
        return FormFigures(
            sag_nm=power, irr_nm=_pv(irregularity), rsi_nm=_pv(symmetric), rmst_nm=_rms(deviation),
            rmsi_nm=_rms(irregularity), rmsa_nm=_rms(irregularity - symmetric), pv_nm=_pv(deviation))

    def deviation_parts(self, values: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """(deviation, irregularity, sagitta) of the values on the area's pixels.

        The deviation is the values less their least-squares piston and tilt, the irregularity
        the values less their best-fit sphere, the sagitta the sphere's power at the test area's
        radius (all in the values' units).
        """
        qt = self._sphere_qt
        projected = qt @ values
        deviation = values - projected[:3] @ qt[:3]
        irregularity = deviation - projected[3] * qt[3]
        power = float(np.linalg.solve(self._sphere_r, projected)[3])
        return deviation, irregularity, power


def _pv(values: NDArray[np.float64]) -> float:
    return float(values.max() - values.min())


def _rms(values: NDArray[np.float64]) -> float:
    return float(np.std(values))
