"""Settings of the simulated optic's surface: where its height map comes from and how it is seen.

:class:`SurfaceSettings` is what :func:`~wavestack.simulators.surface_sources.initial_heights_nm`
builds the starting height map from (Zernike terms, a measured map file, mid-spatial roughness;
the three add) and how :class:`~wavestack.simulators.optic.TestOptic` turns heights into the
wavefront it renders (``reflection_factor``, ``wavelength_nm``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from wavestack.simulators._checks import check_seed, finite_number

__all__ = ["MAP_FILE_SUFFIXES", "SurfaceSettings", "check_figure_sources"]

#: Files a measured map may come from (the instrument files of ``read_measured_map`` and ``.npy`` in nm).
MAP_FILE_SUFFIXES = (".dat", ".datx", ".h5", ".npy")


@dataclass(frozen=True)
class SurfaceSettings:
    """The surface of the simulated test optic, as a height map in nm on the camera grid.

    Attributes
    ----------
    zernike_nm : tuple of float
        Noll-ordered coefficients ``c_1, c_2, ...`` (piston first) of the surface, nm of height,
        unit-RMS over the initial aperture's circumscribing disk (as ``OpticSettings.zernike_waves``);
        empty for none.
    map_file : str or None
        A measured map (``.dat``, ``.datx``, 4D ``.h5``, or a ``.npy`` array in nm, NaN where not
        measured), scaled so that its measured region spans the aperture's circumscribing disk. A
        relative name is read from the working directory (a station file's from the file's folder).
    map_rms_nm : float or None
        RMS (piston removed) of the measured map over the aperture, nm, ``> 0``; None keeps the
        file's own heights. Only with ``map_file``.
    roughness_rms_nm : float
        RMS of the mid-spatial roughness over the aperture, nm, ``>= 0`` (0: none).
    roughness_correlation_mm : float
        Its correlation length (the autocorrelation falls to ``1/e`` there), mm, ``>= pixel_mm``.
    seed : int
        Seed of the roughness, ``>= 0``.
    pixel_mm : float
        Size of a camera pixel on the optic, mm, ``> 0``.
    reflection_factor : float
        Wavefront per surface height, ``> 0``: 2.0 for reflection at normal incidence.
    wavelength_nm : float
        Test wavelength, nm, ``> 0``: wavefront (waves) = ``reflection_factor * heights / wavelength``.

    Raises
    ------
    ValueError
        If a field is out of range; the message names it.

    Examples
    --------
    >>> SurfaceSettings(zernike_nm=(0.0, 0.0, 0.0, 40.0), roughness_rms_nm=2.0).reflection_factor
    2.0
    """

    zernike_nm: tuple[float, ...] = ()
    map_file: str | None = None
    map_rms_nm: float | None = None
    roughness_rms_nm: float = 0.0
    roughness_correlation_mm: float = 1.0
    seed: int = 0
    pixel_mm: float = 0.1
    reflection_factor: float = 2.0
    wavelength_nm: float = 632.8

    def __post_init__(self) -> None:
        if not isinstance(self.zernike_nm, tuple):
            raise ValueError(f"zernike_nm: expected a tuple of numbers, got {type(self.zernike_nm).__name__}")
        check_figure_sources(self.zernike_nm, self.map_file, self.map_rms_nm)
        finite_number(self.roughness_rms_nm, "roughness_rms_nm", minimum=0.0)
        finite_number(self.pixel_mm, "pixel_mm", above=0.0)
        correlation = finite_number(self.roughness_correlation_mm, "roughness_correlation_mm", above=0.0)
        if self.roughness_rms_nm > 0 and correlation < self.pixel_mm:
            raise ValueError(f"roughness_correlation_mm: expected >= pixel_mm ({self.pixel_mm} mm): a correlation "
                             f"shorter than a pixel is not resolved on the grid, got {correlation}")
        check_seed(self.seed)
        finite_number(self.reflection_factor, "reflection_factor", above=0.0)
        finite_number(self.wavelength_nm, "wavelength_nm", above=0.0)

    @property
    def waves_per_nm(self) -> float:
        """Wavefront (waves) per nm of surface height, ``reflection_factor / wavelength_nm``."""
        return self.reflection_factor / self.wavelength_nm


def check_figure_sources(zernike_nm: tuple[float, ...], map_file: str | None, map_rms_nm: float | None) -> None:
    """Check a figure given as Zernike terms (nm) and/or a map file scaled to an RMS (a surface's or a reference's).

    Raises
    ------
    ValueError
        A non-finite term, a map file of another kind, ``map_rms_nm`` without a map or not ``> 0``.
    """
    for index, value in enumerate(zernike_nm):
        finite_number(value, f"zernike_nm[{index}]")
    if map_file is not None:
        if not isinstance(map_file, str) or not map_file:
            raise ValueError(f"map_file: expected a file name, got {map_file!r}")
        if Path(map_file).suffix.lower() not in MAP_FILE_SUFFIXES:
            raise ValueError(f"map_file: expected a {', '.join(MAP_FILE_SUFFIXES)} file, got {map_file!r}")
    if map_rms_nm is not None:
        if map_file is None:
            raise ValueError("map_rms_nm: given without map_file; expected both or neither")
        finite_number(map_rms_nm, "map_rms_nm", above=0.0)
