"""Every surface figure of one measurement, from one request: the entry every command uses.

:class:`SurfaceRequest` says what to measure (the drawing's tolerance, a PSD band, a slope
integration length, a filter); :class:`SurfaceAnalyzer` checks it against the measured area and
its sampling once (a band the pixels cannot resolve, a length shorter than two pixels and a
cut-off outside the area are refused before any map is measured), factorises what can be
factorised, and then measures any number of surfaces on that area into frozen
:class:`SurfaceFigures`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._checks import positive_float
from .area import MeasuredArea, measured_area
from .areal_filter import ArealFilter, filter_surface
from .compliance import SpecVerdict, check_form
from .form import FormAnalyzer, FormFigures
from .fringes import DEFAULT_TEST_WAVELENGTH_NM, fringe_nm
from .power_law import PowerLaw
from .psd import SurfacePsd, check_band, psd_window, resolvable_band, surface_psd
from .robust_pv import RobustPV, RobustPVAnalyzer
from .slope import SlopeMaps, check_integration_length, slope_maps
from .tolerance import FormTolerance

__all__ = ["BandFigures", "FilteredSurface", "SurfaceAnalyzer", "SurfaceFigures", "SurfaceRequest"]


@dataclass(frozen=True)
class SurfaceRequest:
    """What to measure of a surface besides the form figures and PVr (always measured).

    Attributes
    ----------
    tolerance : FormTolerance, optional
        The drawing's form tolerance: adds pass/fail per quantity.
    wavelength_nm : float, optional
        The wavelength fringes are counted at; default the tolerance's, else 546.07 nm.
    psd : bool
        Compute the PSD (2-D and azimuthal average).
    band_per_mm : (float, float), optional
        Band-limited RMS and a power-law fit over this band (cycles/mm; implies ``psd``);
        default with ``psd``: the whole resolvable band.
    slope_length_mm : float, optional
        RMS slope over this integration length.
    areal_filter : ArealFilter, optional
        The filtered surface and its RMS and PV.
    """

    tolerance: FormTolerance | None = None
    wavelength_nm: float | None = None
    psd: bool = False
    band_per_mm: tuple[float, float] | None = None
    slope_length_mm: float | None = None
    areal_filter: ArealFilter | None = None

    @property
    def fringe_wavelength_nm(self) -> float:
        """The wavelength fringes are counted at."""
        if self.wavelength_nm is not None:
            return self.wavelength_nm
        return self.tolerance.wavelength_nm if self.tolerance is not None else DEFAULT_TEST_WAVELENGTH_NM

    @property
    def spectral(self) -> bool:
        """Whether the request holds the heavier, FFT-based figures (PSD, filter)."""
        return self.psd or self.band_per_mm is not None or self.areal_filter is not None

    @property
    def needs_pixel(self) -> bool:
        """Whether the request needs the pixel pitch (PSD, slope, filter)."""
        return self.spectral or self.slope_length_mm is not None


@dataclass(frozen=True)
class BandFigures:
    """The band-limited RMS and the power law over one band.

    Attributes
    ----------
    band_per_mm : (float, float)
    rms_nm : float
    power_law : PowerLaw
    """

    band_per_mm: tuple[float, float]
    rms_nm: float
    power_law: PowerLaw


@dataclass(frozen=True, eq=False)
class FilteredSurface:
    """A filtered surface and its figures.

    Attributes
    ----------
    areal_filter : ArealFilter
    surface_nm : ndarray, shape (rows, cols)
        NaN outside the measured area.
    rms_nm, pv_nm : float
    """

    areal_filter: ArealFilter
    surface_nm: NDArray[np.float64]
    rms_nm: float
    pv_nm: float


@dataclass(frozen=True, eq=False)
class SurfaceFigures:
    """Every figure of one surface.

    Attributes
    ----------
    wavelength_nm : float
        The wavelength of the fringes reported.
    form : FormFigures
    pvr : RobustPV
        In nm.
    verdict : SpecVerdict or None
    psd : SurfacePsd or None
    band : BandFigures or None
    slope : SlopeMaps or None
    filtered : FilteredSurface or None
    """

    wavelength_nm: float
    form: FormFigures
    pvr: RobustPV
    verdict: SpecVerdict | None = None
    psd: SurfacePsd | None = None
    band: BandFigures | None = None
    slope: SlopeMaps | None = None
    filtered: FilteredSurface | None = None

    def as_dict(self, *, spectra: bool = True) -> dict[str, object]:
        """JSON-ready form (``spectra=False`` leaves out the PSD's arrays)."""
        wavelength = self.wavelength_nm
        out: dict[str, object] = {
            "form": self.form.as_dict(wavelength),
            "pvr": {"nm": self.pvr.pvr, "fringes": self.pvr.pvr / fringe_nm(wavelength),
                    "waves": self.pvr.pvr / wavelength, "fit_pv_nm": self.pvr.fit_pv,
                    "residual_rms_nm": self.pvr.residual_rms},
        }
        if self.verdict is not None:
            out["spec"] = self.verdict.as_dict()
        if self.psd is not None:
            psd: dict[str, object] = {"resolvable_per_mm": list(self.psd.resolvable_per_mm)}
            if self.band is not None:
                psd.update(band_per_mm=list(self.band.band_per_mm), band_rms_nm=self.band.rms_nm,
                           power_law=self.band.power_law.as_dict())
            if spectra:
                psd.update(frequency_per_mm=self.psd.frequency_per_mm.tolist(),
                           azimuthal_nm2_mm2=self.psd.azimuthal_nm2_mm2.tolist(),
                           radial_nm2_mm=self.psd.radial_nm2_mm.tolist())
            out["psd"] = psd
        if self.slope is not None:
            out["slope"] = self.slope.figures().as_dict()
        if self.filtered is not None:
            out["filtered"] = {**self.filtered.areal_filter.as_dict(), "rms_nm": self.filtered.rms_nm,
                               "pv_nm": self.filtered.pv_nm}
        return out


class SurfaceAnalyzer:
    """Measures surfaces on one measured area against one request.

    Parameters
    ----------
    valid : array_like of bool, shape (rows, cols)
        The measured pixels.
    request : SurfaceRequest
    pixel_mm : float, optional
        Pixel pitch (square pixels), mm; needed by the PSD, slopes and filters.

    Raises
    ------
    ValueError
        One line naming the input and what was expected: a request that needs the pixel pitch
        without one, a band the sampling cannot resolve, an integration length shorter than two
        pixels or not shorter than the area, a cut-off outside two pixels to the area's extent,
        too few measured pixels.

    Examples
    --------
    >>> import numpy as np
    >>> from wavestack.pipeline.surface import parse_form_tolerance
    >>> rows, cols = np.mgrid[:65, :65]
    >>> x, y = (cols - 32) / 32, (32 - rows) / 32
    >>> disk = x**2 + y**2 <= 1
    >>> analyzer = SurfaceAnalyzer(disk, SurfaceRequest(tolerance=parse_form_tolerance("3/1(0.5/0.2)")))
    >>> figures = analyzer.measure(150 * (x**2 + y**2) + 30 * x * y)
    >>> figures.verdict.passed, round(figures.form.sag_nm, 6)
    (True, 150.0)
    """

    def __init__(self, valid: ArrayLike, request: SurfaceRequest, pixel_mm: float | None = None) -> None:
        self.request = request
        self.area: MeasuredArea = measured_area(valid)
        self.pixel_mm = None if pixel_mm is None else positive_float(pixel_mm, "pixel_mm")
        self._check_sampling()
        self._form = FormAnalyzer(self.area)
        self._pvr = RobustPVAnalyzer(self.area)
        self._window = psd_window(self.area) if request.psd or request.band_per_mm is not None else None

    def _check_sampling(self) -> None:
        request = self.request
        if not request.needs_pixel:
            return
        if self.pixel_mm is None:
            raise ValueError("pixel size: the PSD, slopes and filters need the pixel pitch; expected it in mm "
                             "(from the file or given)")
        extent_mm = 2.0 * self.area.pupil.radius * self.pixel_mm
        if request.band_per_mm is not None:
            check_band(request.band_per_mm, resolvable_band(self.area, self.pixel_mm), "PSD band")
        if request.slope_length_mm is not None:
            check_integration_length(request.slope_length_mm, self.pixel_mm, extent_mm)
        if request.areal_filter is not None:
            request.areal_filter.check_resolvable(self.pixel_mm, extent_mm)

    def measure(self, surface_nm: ArrayLike, *, spectral: bool = True) -> SurfaceFigures:
        """Every requested figure of one surface.

        Parameters
        ----------
        surface_nm : array_like, shape (rows, cols)
            Surface height, nm, finite on every measured pixel.
        spectral : bool
            Also the FFT-based figures (PSD, filter) when requested; the live station computes
            them every few results only.

        Raises
        ------
        ValueError
            If the map's shape differs from the area's or a measured pixel is not finite.
        """
        request = self.request
        form = self._form.figures(surface_nm)
        verdict = check_form(form, request.tolerance) if request.tolerance is not None else None
        figures = SurfaceFigures(wavelength_nm=request.fringe_wavelength_nm, form=form,
                                 pvr=self._pvr.measure(surface_nm), verdict=verdict)
        pixel = self.pixel_mm
        if request.slope_length_mm is not None and pixel is not None:
            figures = replace(figures, slope=slope_maps(self.area, surface_nm, pixel, request.slope_length_mm))
        if spectral and request.spectral and pixel is not None:
            figures = self._spectral(figures, surface_nm, pixel)
        return figures

    def _spectral(self, figures: SurfaceFigures, surface_nm: ArrayLike, pixel_mm: float) -> SurfaceFigures:
        request = self.request
        if request.psd or request.band_per_mm is not None:
            psd = surface_psd(self.area, surface_nm, pixel_mm, window=self._window)
            low, high = request.band_per_mm or psd.resolvable_per_mm
            band = BandFigures(band_per_mm=(low, high), rms_nm=psd.band_rms_nm(low, high),
                               power_law=psd.power_law(low, high))
            figures = replace(figures, psd=psd, band=band)
        if request.areal_filter is not None:
            filtered = filter_surface(self.area, surface_nm, pixel_mm, request.areal_filter)
            values = filtered[self.area.valid]
            figures = replace(figures, filtered=FilteredSurface(
                areal_filter=request.areal_filter, surface_nm=filtered, rms_nm=float(np.std(values)),
                pv_nm=float(values.max() - values.min())))
        return figures
