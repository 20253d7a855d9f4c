"""``[processing]``: how an interferometer station turns frames into coefficients, and what its fitters are built with."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from wavestack.config.schema import setting


@dataclass(frozen=True)
class FitSettings:
    """What a fitter is built with (see :func:`wavestack.pipeline.build_fitter`)."""

    method: str = "csf-qcm"
    modes: int = 36
    ordering: str = "noll"
    remove: str | None = "ptt"
    mesh_vertices: int = 15000


@dataclass(frozen=True)
class ProcessingSettings:
    """How frames become coefficients (the ``[processing]`` table of a station config)."""

    method: Literal["psi", "carrier"] = setting("psi", doc="phase-shifted sets or single carrier frames")
    psi_algorithm: Literal["lsq", "four", "hariharan", "aia", "pca"] = "lsq"
    steps_deg: tuple[float, ...] = setting((0.0, 90.0, 180.0, 270.0), minimum=-720.0, maximum=720.0,
                                           doc="phase steps of a set, degrees")
    carrier_sign: Literal[1, -1] = 1
    modes: int = setting(36, minimum=3, maximum=231)
    ordering: Literal["noll", "ansi", "fringe"] = "noll"
    fit_method: Literal["csf-qcm", "conformal", "qr", "circle"] = "csf-qcm"
    remove: Literal["ptt", "pttp", "none"] = "ptt"
    fit_decimation: int = setting(2, minimum=1, maximum=8, doc="fit every n-th pixel in each direction")
    iou_threshold: float = setting(0.98, minimum=0.5, maximum=1.0)
    watch_block_px: int = setting(4, minimum=1, maximum=32)
    max_residues: int = setting(0, minimum=0)
    unwrap_prefilter_px: float = setting(1.5, minimum=0.0, maximum=10.0)
    mesh_vertices: int = setting(8000, minimum=500, maximum=200000,
                                 doc="CSF-QCM mesh size; 8000 builds in ~0.4 s at 512 x 512 samples")
    max_residual_waves: float = setting(0.1, minimum=0.0, maximum=100.0,
                                        doc="a fit whose residual RMS exceeds this is flagged invalid, waves")

    @property
    def frames_per_set(self) -> int:
        return len(self.steps_deg) if self.method == "psi" else 1

    def fit_settings(self) -> FitSettings:
        return FitSettings(self.fit_method, self.modes, self.ordering, None if self.remove == "none" else self.remove,
                           self.mesh_vertices)
