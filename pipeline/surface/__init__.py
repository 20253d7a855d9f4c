"""Spec-grade surface figures: what a drawing tolerances and a shop signs.

From a surface height map (nm) on its measured pixels, nothing filled:

* the ISO 14999-4 form figures SAG, IRR, RSI, RMSt, RMSi, RMSa (:class:`FormAnalyzer`), in nm,
  fringes (half the test wavelength, 546.07 nm unless stated) and waves;
* the drawing's ISO 10110-5 tolerance ``3/A(B/C; RMSx < D)`` read or refused with the reason
  (:func:`parse_form_tolerance`) and checked quantity by quantity (:func:`check_form`);
* PVr, Evans' robust PV (:class:`RobustPVAnalyzer`);
* the windowed PSD, 2-D and azimuthally averaged, band-limited RMS and a power-law fit
  (:func:`surface_psd`);
* slope maps and RMS slope over an integration length, urad (:func:`slope_maps`);
* areal Gaussian low-, high- and band-pass filters normalised inside the area (:func:`filter_surface`).

:class:`SurfaceAnalyzer` does all of them for a :class:`SurfaceRequest`, checked against the
area and its sampling once; every command (analyze, fit, the station, polishing) measures
through it. The topic sits above ``fit`` (PVr's fit, the physical piston, tilt and power).
"""

from __future__ import annotations

from .area import MeasuredArea, measured_area
from .areal_filter import ALPHA, ArealFilter, filter_surface, gaussian_transmission, parse_areal_filter
from .compliance import QuantityCheck, SpecVerdict, check_form
from .figures import BandFigures, FilteredSurface, SurfaceAnalyzer, SurfaceFigures, SurfaceRequest
from .form import FormAnalyzer, FormFigures
from .fringes import DEFAULT_TEST_WAVELENGTH_NM, fringe_nm
from .power_law import PowerLaw, fit_power_law
from .psd import PsdWindow, SurfacePsd, aperture_outline, aperture_window, check_band, psd_window, resolvable_band
from .psd import surface_psd
from .radial import RadialModel
from .robust_pv import PVR_MODES, RobustPV, RobustPVAnalyzer
from .slope import SlopeFigures, SlopeMaps, check_integration_length, slope_maps
from .tolerance import FORM_QUANTITIES, FormTolerance, ToleranceError, parse_form_tolerance

__all__ = [
    "ALPHA",
    "ArealFilter",
    "BandFigures",
    "DEFAULT_TEST_WAVELENGTH_NM",
    "FORM_QUANTITIES",
    "FilteredSurface",
    "FormAnalyzer",
    "FormFigures",
    "FormTolerance",
    "MeasuredArea",
    "PVR_MODES",
    "PowerLaw",
    "PsdWindow",
    "QuantityCheck",
    "RadialModel",
    "RobustPV",
    "RobustPVAnalyzer",
    "SlopeFigures",
    "SlopeMaps",
    "SpecVerdict",
    "SurfaceAnalyzer",
    "SurfaceFigures",
    "SurfacePsd",
    "SurfaceRequest",
    "ToleranceError",
    "aperture_outline",
    "aperture_window",
    "check_band",
    "check_form",
    "check_integration_length",
    "filter_surface",
    "fit_power_law",
    "fringe_nm",
    "gaussian_transmission",
    "measured_area",
    "parse_areal_filter",
    "parse_form_tolerance",
    "psd_window",
    "resolvable_band",
    "slope_maps",
    "surface_psd",
]
