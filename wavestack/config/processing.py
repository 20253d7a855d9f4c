"""``[processing]``: how an interferometer station turns frames into coefficients, and what its fitters are built with.

The table only declares and checks the settings; :meth:`ProcessingSettings.interferometer` gives
them to the one processor (:mod:`wavestack.pipeline.instrument`) that the station, ``replay``,
``batch`` and ``analyze --config`` all run.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Literal

import numpy as np

from wavestack.config.schema import ConfigError, setting
from wavestack.pipeline.instrument import FitSettings, InterferometerSettings, QualitySettings

#: Steps each fixed-step algorithm assumes, degrees from the first (the station steps counter-clockwise).
FIXED_STEPS_DEG: Final = {"four": (0.0, 90.0, 180.0, 270.0), "hariharan": (0.0, 90.0, 180.0, 270.0, 360.0)}
#: Most frames in one phase-shifted set (each set is held in memory ``set_ring_capacity`` times).
MAX_STEPS: Final = 32
#: Largest accepted condition number of the least-squares design ``[1, cos d, -sin d]`` of the steps: the
#: phase noise grows with it (four 90 degree steps: 1.41; 0/45/90 degrees: 12; 0/30/60 degrees: 29).
MAX_STEP_CONDITION: Final = 20.0
_STEP_TOLERANCE_DEG = 1e-6


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
    fit_method: Literal["csf-qcm", "conformal", "qr", "circle", "annulus"] = "csf-qcm"
    obscuration: float | None = setting(None, minimum=0.0, maximum=1.0,
                                        doc="annulus only: inner over outer radius, 0 < E < 1 (absent: measured "
                                            "from the aperture's central hole)")
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
    fit_dtype: Literal["float32", "float64"] = setting("float32", doc="the fitters' operator and per-frame product")
    carrier_refresh_sets: int = setting(32, minimum=1, maximum=100000,
                                        doc="carrier method: search the carrier at least every this many frames")
    min_modulation: float = setting(0.1, minimum=0.0, maximum=1.0,
                                    doc="pixels below this fraction of the aperture's mean modulation are not fitted")
    check_fringe_order: bool = setting(True, doc="leave out pixels whose fringe order is not trusted")
    spike_clip: bool = setting(True, doc="leave out pixels whose fit residual exceeds clip_sigma residual RMS")
    clip_sigma: float = setting(6.0, minimum=1.0, maximum=1000.0, doc="the spike clip's limit, in residual RMS")
    calibration: str | None = setting(None, doc="a reference calibration (wavestack calibrate --out), subtracted "
                                                "from every map; a path relative to this file")

    @property
    def frames_per_set(self) -> int:
        return len(self.steps_deg) if self.method == "psi" else 1

    def check(self, *, source: str) -> None:
        """Refuse phase steps the algorithm cannot work with (``method = "psi"`` only), and an
        ``obscuration`` outside (0, 1) or without ``fit_method = "annulus"``.

        Rules: 3 to :data:`MAX_STEPS` steps; ``four`` and ``hariharan`` take exactly their own
        steps (:data:`FIXED_STEPS_DEG`, from any first step); ``lsq``, ``aia`` and ``pca`` need at
        least three steps distinct modulo 360 degrees, spread over the cycle (condition number of
        the least-squares design at most :data:`MAX_STEP_CONDITION`).

        Raises
        ------
        ConfigError
            One line naming ``source``, the key (``[processing] steps_deg`` or ``obscuration``), the
            value and the rule.
        """
        problem = _obscuration_problem(self.fit_method, self.obscuration)
        if problem is not None:
            raise ConfigError(f"{source}: [processing] obscuration = {self.obscuration!r}: {problem}")
        if self.method != "psi":
            return
        shown = ", ".join(f"{step:g}" for step in self.steps_deg[:8]) + (", ..." if len(self.steps_deg) > 8 else "")
        where = f"{source}: [processing] steps_deg = [{shown}]"
        reason = _step_problem(self.psi_algorithm, self.steps_deg)
        if reason is not None:
            raise ConfigError(f"{where}: {reason} (psi_algorithm = {self.psi_algorithm!r})")

    def fit_settings(self) -> FitSettings:
        return FitSettings(self.fit_method, self.modes, self.ordering, None if self.remove == "none" else self.remove,
                           self.mesh_vertices, self.obscuration, self.fit_dtype)

    def interferometer(self, *, saturation_counts: float | None = None) -> InterferometerSettings:
        """These settings as the interferometer processor takes them.

        ``saturation_counts``: the camera's full scale (None: the frames' integer type's).
        """
        quality = QualitySettings(self.min_modulation, saturation_counts, self.check_fringe_order)
        return InterferometerSettings(
            method=self.method, psi_algorithm=self.psi_algorithm, steps_rad=tuple(np.radians(self.steps_deg)),
            carrier_sign=self.carrier_sign, carrier_refresh_sets=self.carrier_refresh_sets,
            fit=self.fit_settings(), fit_decimation=self.fit_decimation, iou_threshold=self.iou_threshold,
            watch_block_px=self.watch_block_px, max_residues=self.max_residues,
            unwrap_prefilter_px=self.unwrap_prefilter_px, max_residual_waves=self.max_residual_waves,
            quality=quality, clip_sigma=self.clip_sigma if self.spike_clip else None)


def _obscuration_problem(fit_method: str, obscuration: float | None) -> str | None:
    """Why an obscuration cannot go with the fit method, or None."""
    if obscuration is None:
        return None
    if fit_method != "annulus":
        return f"expected only with fit_method = \"annulus\" (fit_method is {fit_method!r})"
    if not 0.0 < obscuration < 1.0:
        return "expected a ratio of inner to outer radius strictly between 0 and 1"
    return None


def _step_problem(algorithm: str, steps_deg: tuple[float, ...]) -> str | None:
    """Why ``steps_deg`` cannot work with ``algorithm``, or None."""
    count = len(steps_deg)
    fixed = FIXED_STEPS_DEG.get(algorithm)
    if fixed is not None:
        expected = [steps_deg[0] + step for step in fixed] if count else list(fixed)
        if count != len(fixed) or not np.allclose(steps_deg, expected, rtol=0.0, atol=_STEP_TOLERANCE_DEG):
            return f"expected {len(fixed)} steps {fixed[1] - fixed[0]:g} degrees apart, e.g. {list(fixed)}"
        return None
    if not 3 <= count <= MAX_STEPS:
        return f"expected 3 to {MAX_STEPS} steps, got {count}"
    wrapped = np.round(np.mod(steps_deg, 360.0), 6) % 360.0
    if len(np.unique(wrapped)) < 3:
        return "expected at least 3 steps distinct modulo 360 degrees"
    radians = np.radians(steps_deg)
    design = np.column_stack([np.ones(count), np.cos(radians), -np.sin(radians)])
    singular = np.linalg.svd(design, compute_uv=False)
    condition = singular[0] / singular[-1] if singular[-1] > 0 else np.inf
    if not condition <= MAX_STEP_CONDITION:
        return (f"expected steps spread over the cycle (least-squares condition number <= {MAX_STEP_CONDITION:g}, "
                f"got {condition:.3g}), e.g. [0, 90, 180, 270]")
    return None
