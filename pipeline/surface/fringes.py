"""Fringe spacings, the unit of drawing tolerances: one fringe is half a test wavelength of surface.

A surface seen in reflection at normal incidence changes the optical path by twice its height,
so one interference fringe is ``lambda / 2`` of surface height (ISO 10110-5). Without a stated
wavelength, drawings mean the mercury e-line, 546.07 nm.
"""

from __future__ import annotations

__all__ = ["DEFAULT_TEST_WAVELENGTH_NM", "fringe_nm"]

#: The test wavelength ISO 10110-5 assumes when a drawing states none (Hg e-line), nm.
DEFAULT_TEST_WAVELENGTH_NM = 546.07


def fringe_nm(wavelength_nm: float) -> float:
    """Surface height of one fringe spacing at ``wavelength_nm``: ``wavelength_nm / 2``, nm.

    >>> fringe_nm(632.8)
    316.4
    """
    return 0.5 * float(wavelength_nm)
