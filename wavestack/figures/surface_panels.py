"""The surface figures' panels of a fit figure: the PSD, the slope map, the filtered surface.

Drawn below the maps and coefficients of :func:`~wavestack.figures.fit_figure.fit_figure` when the
command measured them (``--psd``, ``--slope-length-mm``, ``--filter``): the azimuthally averaged
PSD on log-log axes with the band shaded and the fitted power law over it, the slope magnitude
in urad, and the filtered surface in nm.
"""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from wavestack.figures.drawing import BAR_COLOUR, MAGNITUDE_CMAP, data_limits, map_panel, symmetric_limits
from wavestack.pipeline import SurfaceFigures

__all__ = ["draw_surface_panels", "surface_panel_count"]


def surface_panel_count(surface: SurfaceFigures | None) -> int:
    """How many panels :func:`draw_surface_panels` draws for these figures (0 to 3)."""
    if surface is None:
        return 0
    return sum(part is not None for part in (surface.psd, surface.slope, surface.filtered))


def draw_surface_panels(figure: Figure, axes: list[Axes], surface: SurfaceFigures) -> None:
    """Draw the PSD, slope and filtered panels into ``axes`` (one each, in that order, as present)."""
    panels = iter(axes)
    if surface.psd is not None:
        _psd_panel(next(panels), surface)
    if surface.slope is not None:
        slope = surface.slope
        magnitude = np.hypot(slope.x_urad, slope.y_urad)
        rms = slope.figures().rms_urad
        map_panel(figure, next(panels), magnitude, title=f"slope over {slope.length_mm:g} mm\nRMS {rms:.4g} urad",
                  unit="slope, urad", limits=data_limits(magnitude), cmap=MAGNITUDE_CMAP)
    if surface.filtered is not None:
        filtered = surface.filtered
        map_panel(figure, next(panels), filtered.surface_nm,
                  title=f"{filtered.areal_filter.describe()}\nRMS {filtered.rms_nm:.4g}, PV {filtered.pv_nm:.4g} nm",
                  unit="surface, nm", limits=symmetric_limits(filtered.surface_nm))


def _psd_panel(axes: Axes, surface: SurfaceFigures) -> None:
    psd = surface.psd
    assert psd is not None
    positive = psd.azimuthal_nm2_mm2 > 0
    axes.loglog(psd.frequency_per_mm[positive], psd.azimuthal_nm2_mm2[positive], color=BAR_COLOUR, lw=1.0,
                label="azimuthal average")
    title = "PSD (windowed, azimuthal average)"
    if surface.band is not None:
        low, high = surface.band.band_per_mm
        law = surface.band.power_law
        axes.axvspan(low, high, color="0.9", zorder=0)
        line = np.geomspace(low, high, 50)
        axes.loglog(line, law.amplitude * line**law.slope, color="C3", lw=1.5,
                    label=f"{law.amplitude:.3g} f^{law.slope:.2f}")
        title += f"\nband RMS {surface.band.rms_nm:.4g} nm"
        axes.legend(loc="lower left", fontsize="small")
    axes.set_xlabel("spatial frequency, cycles/mm")
    axes.set_ylabel("PSD, nm^2 mm^2")
    axes.set_title(title)
