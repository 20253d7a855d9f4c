"""What the machine's panel shows of one result: the PLC's display block from a station result (pure).

The station writes it every cycle through the link that owns the PLC (:mod:`.outputs`); the
block's layout and codes are the driver's (:mod:`wavestack.drivers.plc.display`, and the table in
docs/instruments.md). Figures are in nm of surface, the same convention as the removal terms
(``waves x wavelength_nm x surface_factor``, docs/conventions.md, "Surface"): the residual RMS is
the Zernike fit's, PVr and the verdict are the surface stage's (``[surface]``).
"""

from __future__ import annotations

import math

from wavestack.drivers.plc import ResultDisplay, SpecCode, invalid_display
from wavestack.station.results import StationResult

__all__ = ["result_display"]


def result_display(result: StationResult, *, surface_nm_per_wave: float, spec_configured: bool) -> ResultDisplay:
    """The display block's values for one result.

    Parameters
    ----------
    result : StationResult
    surface_nm_per_wave : float
        nm of surface per wave of measured wavefront (``wavelength_nm x surface_factor``).
    spec_configured : bool
        The station checks a drawing tolerance: a result without a verdict is then "not judged",
        never "no spec".

    Returns
    -------
    ResultDisplay
        Invalid (no figures, the verdict not judged) for an invalid result or one without a finite
        residual; else valid, with PVr when the surface figures were measured and the verdict
        (pass/fail and the limiting quantity) when they were judged.

    Examples
    --------
    >>> from wavestack.station.counters import Counters
    >>> lost = StationResult.invalid(7, "device: gone", Counters.zero(5), ordering="noll")
    >>> result_display(lost, surface_nm_per_wave=316.4, spec_configured=True)
    ResultDisplay(result_index=7, valid=False, residual_rms_nm=0.0, pvr_nm=None, spec=<SpecCode.NOT_JUDGED: 3>, limiting='')
    """
    residual_nm = result.residual_rms * surface_nm_per_wave
    if not (result.valid and math.isfinite(residual_nm)):
        return invalid_display(result.index, has_spec=spec_configured)
    surface = result.surface
    pvr = surface.pvr.pvr if surface is not None and math.isfinite(surface.pvr.pvr) else None
    verdict = surface.verdict if surface is not None else None
    if verdict is not None:
        spec, limiting = (SpecCode.PASS if verdict.passed else SpecCode.FAIL), verdict.limiting.quantity
    else:
        spec, limiting = (SpecCode.NOT_JUDGED if spec_configured else SpecCode.NO_SPEC), ""
    return ResultDisplay(result.index, True, abs(residual_nm), pvr, spec, limiting)
