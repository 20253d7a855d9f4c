"""The small frozen records an instrument processor's outcome carries into a result.

:class:`ApertureRecord` says which aperture a result was measured on (an interferometer's
detected aperture, a Shack-Hartmann sensor's set of lit lenslets); :class:`FitDiagnostics` an
interferometer fitter's figures, :class:`ReconstructorDiagnostics` a Shack-Hartmann
reconstructor's. Each has a ``to_json`` giving the keys the station's
JSON lines and recordings carry.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class ApertureRecord:
    """The aperture a result was measured on.

    Attributes
    ----------
    id : int or None
        Counted per run from 0 (interferometer: per aperture; Shack-Hartmann: per lit-lenslet set).
    changed : bool
        This set started it.
    topology : str
        A one-line description (interferometer: the aperture's topology and pixel count).
    valid_pixels : int
    components : int or None
        Interferometer: connected components of the aperture.
    valid_lenslets : int or None
        Shack-Hartmann: lit lenslets used.
    """

    id: int | None
    changed: bool
    topology: str
    valid_pixels: int
    components: int | None = None
    valid_lenslets: int | None = None

    def to_json(self) -> dict[str, object]:
        """The record's keys as the JSON lines carry them (absent optional figures left out)."""
        record: dict[str, object] = {"id": self.id, "changed": self.changed, "topology": self.topology}
        if self.components is not None:
            record["components"] = self.components
        if self.valid_lenslets is not None:
            record["valid_lenslets"] = self.valid_lenslets
        record["valid_pixels"] = self.valid_pixels
        return record


@dataclass(frozen=True)
class FitDiagnostics:
    """A mapped or QR fitter's figures: Gram condition number, map fold-overs, largest Beltrami coefficient."""

    gram_condition: float | None
    flips: int | None
    max_beltrami: float | None

    def to_json(self) -> dict[str, object]:
        return asdict(self)


@dataclass(frozen=True)
class ReconstructorDiagnostics:
    """A Shack-Hartmann modal reconstructor's figures: condition number, lit and pupil lenslets."""

    condition: float
    lit_lenslets: int
    pupil_lenslets: int

    def to_json(self) -> dict[str, object]:
        return asdict(self)
