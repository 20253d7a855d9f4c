"""What the test optic precomputes for one aperture and one turn of the part (:class:`Rendering`).

:func:`prepare_rendering` evaluates, once per aperture or rotation, the optic's wavefront ``W0 = B c``
(and the drift's ``B d``) on the aperture pixels, adds the reference's error, and makes the phase,
amplitude and offset arrays a frame is rendered from. The part's Zernike figure is evaluated at the
part's own coordinates: turned counter-clockwise by ``a`` on its mount, the camera's disk point
``(u, v)`` sees the part's point ``R(-a) (u, v)``. The reference's error
(:func:`reference_waves`) is evaluated at the camera's ``(u, v)``: it does not turn. Conventions
(pixel coordinates, the unit disk) are those of :mod:`wavestack.simulators.optic`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wavestack.pipeline import Aperture, mode_list, zernike_basis
from wavestack.simulators._checks import read_only
from wavestack.simulators.aperture_shape import ApertureShape
from wavestack.simulators.calibration_ball import CalibrationBall
from wavestack.simulators.optic_settings import OpticSettings, ReferenceSettings
from wavestack.simulators.surface_sources import measured_surface_nm

__all__ = ["Rendering", "prepare_rendering", "reference_waves"]

_BASIS_BLOCK = 1 << 15  # aperture pixels per block when evaluating the basis


@dataclass(frozen=True, eq=False)
class Rendering:
    """Everything precomputed for one aperture; replaced whole by ``set_aperture`` and ``rotate_part``."""

    shape: ApertureShape
    revision: int
    mask: NDArray[np.bool_]
    pupil: tuple[float, float, float]
    wavefront: NDArray[np.float64]  # W0 = B c, NaN outside
    wavefront_drift: NDArray[np.float64] | None  # D = B d, NaN outside
    phase: NDArray[np.float32]  # 2 pi W0 + carrier modulo 2 pi, radians (finite everywhere)
    phase_drift: NDArray[np.float32] | None  # 2 pi D, radians per second, 0 outside
    amplitude: NDArray[np.float32]  # modulation counts inside, 0 outside
    offset: NDArray[np.float32]  # background counts inside, halo counts outside
    index: NDArray[np.intp] | None = None  # with a surface: flat indices of the aperture pixels
    base_phase: NDArray[np.float64] | None = None  # with a surface: 2 pi W0 + carrier there, not wrapped
    rotation_deg: float = 0.0  # the part's rotation rendered
    reference: NDArray[np.float64] | None = None  # the reference's error, waves, NaN outside


def prepare_rendering(settings: OpticSettings, size: tuple[int, int], shape: ApertureShape, revision: int, *,
                      modes: tuple[tuple[int, int], ...], coefficients: NDArray[np.float64],
                      drift: NDArray[np.float64] | None, rotation_deg: float, with_surface: bool,
                      ball: CalibrationBall | None = None) -> Rendering:
    """Everything a frame on ``shape`` needs, with the part turned by ``rotation_deg`` (module notes).

    ``ball``: a calibration ball in its current seating, whose cap adds to the wavefront.

    Raises
    ------
    ValueError
        If the aperture covers no pixel of the frame.
    """
    height, width = size
    mask = shape.mask(height, width)
    if not mask.any():
        raise ValueError(f"aperture {shape} covers no pixel of the {height} x {width} frame")
    cx, cy, radius = Aperture.from_mask(mask).enclosing_circle()
    rows, cols = np.nonzero(mask)
    u, v = (cols - cx) / radius, (cy - rows) / radius
    # the part turned by a (counter-clockwise): the camera's point (u, v) sees the part's R(-a)(u, v)
    turn = math.radians(rotation_deg)
    part_u, part_v = u * math.cos(turn) + v * math.sin(turn), v * math.cos(turn) - u * math.sin(turn)
    vectors = [coefficients] + ([] if drift is None else [drift])
    products = _basis_products(modes, part_u, part_v, np.column_stack(vectors))
    reference_map = None
    if settings.reference is not None:
        reference = reference_waves(settings.reference, mask, u, v)
        products[:, 0] += reference
        reference_map = np.full((height, width), np.nan)
        reference_map[rows, cols] = reference
        reference_map = read_only(reference_map)
    if ball is not None:
        products[:, 0] += ball.cap_nm(u, v) / ball.settings.wavelength_nm
    maps = []
    for k in range(len(vectors)):
        values = np.full((height, width), np.nan)
        values[rows, cols] = products[:, k]
        maps.append(read_only(values))
    ny, nx = np.indices((height, width), dtype=np.float64) if any(settings.carrier_cycles) else (0.0, 0.0)
    carrier = 2.0 * np.pi * (settings.carrier_cycles[0] * nx / width - settings.carrier_cycles[1] * ny / height)
    # wrapped before the cast: float32 then holds the phase to 2.4e-7 rad whatever its size
    phase = np.mod(2.0 * np.pi * np.where(mask, maps[0], 0.0) + carrier, 2.0 * np.pi).astype(np.float32)
    phase_drift = None
    if len(maps) > 1:
        phase_drift = read_only((2.0 * np.pi * np.where(mask, maps[1], 0.0)).astype(np.float32))
    index = base_phase = None
    if with_surface:
        index = np.flatnonzero(mask)
        base_phase = 2.0 * np.pi * products[:, 0] + (carrier.reshape(-1)[index] if np.ndim(carrier) else carrier)
    scale = settings.full_scale
    amplitude = np.where(mask, np.float32(settings.modulation * scale), np.float32(0.0))
    offset = np.where(mask, np.float32(settings.background * scale), np.float32(settings.halo * scale))
    return Rendering(
        shape=shape, revision=revision, mask=read_only(mask), pupil=(cx, cy, radius),
        wavefront=maps[0], wavefront_drift=maps[1] if len(maps) > 1 else None,
        phase=read_only(phase), phase_drift=phase_drift,
        amplitude=read_only(amplitude), offset=read_only(offset), index=index, base_phase=base_phase,
        rotation_deg=rotation_deg, reference=reference_map,
    )


def _basis_products(modes: tuple[tuple[int, int], ...], u: NDArray[np.float64], v: NDArray[np.float64],
                    vectors: NDArray[np.float64]) -> NDArray[np.float64]:
    """``B @ vectors`` with ``B`` the unit-RMS Zernike basis at ``(u, v)``, evaluated in blocks (not kept)."""
    products = np.empty((u.size, vectors.shape[1]))
    for start in range(0, u.size, _BASIS_BLOCK):
        block = slice(start, start + _BASIS_BLOCK)
        products[block] = zernike_basis(modes, u[block], v[block]) @ vectors
    return products


def reference_waves(settings: ReferenceSettings, mask: NDArray[np.bool_], u: NDArray[np.float64],
                    v: NDArray[np.float64]) -> NDArray[np.float64]:
    """The reference's error on the aperture pixels (row-major order of ``mask``), waves of wavefront.

    Its Zernike terms at the disk coordinates ``(u, v)`` of those pixels, plus its map file scaled
    onto the aperture's disk (:func:`~wavestack.simulators.surface_sources.measured_surface_nm`).
    """
    values = np.zeros(u.size)
    if settings.zernike_nm:
        terms = np.asarray(settings.zernike_nm, dtype=np.float64)[:, None]
        values += _basis_products(tuple(mode_list("noll", terms.shape[0])), u, v, terms)[:, 0]
    if settings.map_file is not None:
        values += measured_surface_nm(settings.map_file, mask, settings.map_rms_nm)[mask]
    return values * settings.waves_per_nm
