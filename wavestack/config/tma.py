"""Configuration of the simulated TMA alignment bench's telescope: table ``[tma]``.

``[tma]`` holds the design (:class:`~wavestack.pipeline.telescope.TmaDesign`): the mirrors as an array
of tables ``[[tma.mirrors]]``, the off-axis pupil ``[tma.pupil]``, field points, wavelength, the
aligned mirror and its pivot, the camera grid; ``[tma.as_built]`` the seeded as-built errors.
Other top-level tables are left to their own loaders. Example: ``wavestack/config/tma-alignment.toml``::

    [tma]
    source = "derived ..."
    wavelength_nm = 632.8
    image_z_mm = 326.158
    field_points_deg = [[0.0, -0.6]]
    [tma.pupil]
    centre_mm = [0.0, 150.0]
    size_mm = [240.0, 80.0]
    [[tma.mirrors]]
    name = "M1"
    radius_mm = 1600.0
    conic = -1.350908
    vertex_z_mm = 0.0
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wavestack.config.schema import ConfigError, load_toml, parse_section, setting
from wavestack.pipeline.telescope import AsBuiltErrors, PupilShape, TmaDesign, TmaMirror


@dataclass(frozen=True)
class TmaMirrorSettings:
    """``[[tma.mirrors]]``: one conic mirror, in the order light meets them."""

    name: str = setting(doc="mirror name, e.g. \"M2\"")
    radius_mm: float = setting(minimum=-1e6, maximum=1e6, doc="vertex radius, mm (+: centre towards +z)")
    conic: float = setting(minimum=-1e3, maximum=1e3, doc="conic constant k")
    vertex_z_mm: float = setting(minimum=-1e5, maximum=1e5, doc="vertex position on the axis, mm")


@dataclass(frozen=True)
class TmaPupilSettings:
    """``[tma.pupil]``: the off-axis rounded-rectangle entrance pupil on the stop plane."""

    centre_mm: tuple[float, float] = setting(minimum=-1e5, maximum=1e5, doc="(x, y) of the centre, mm")
    size_mm: tuple[float, float] = setting(minimum=1e-3, maximum=1e5, doc="(width along x, height along y), mm")
    corner_radius_mm: float = setting(0.0, minimum=0.0, maximum=1e5, doc="corner radius, mm")


@dataclass(frozen=True)
class TmaAsBuiltSettings:
    """``[tma.as_built]``: RMS rigid-body errors of the mirrors the hexapod does not carry."""

    decentre_mm_rms: float = setting(0.0, minimum=0.0, maximum=10.0, doc="x, y decentre RMS, mm")
    despace_mm_rms: float = setting(0.0, minimum=0.0, maximum=10.0, doc="z despace RMS, mm")
    tilt_deg_rms: float = setting(0.0, minimum=0.0, maximum=1.0, doc="tilt RMS about x and y, deg")
    seed: int = setting(0, minimum=0, doc="seed of the draw")


@dataclass(frozen=True)
class TmaSettings:
    """``[tma]``: the telescope design and the interferometer's camera grid."""

    source: str = setting(doc="where the prescription comes from")
    wavelength_nm: float = setting(minimum=100.0, maximum=20000.0, doc="test wavelength, nm")
    image_z_mm: float = setting(minimum=-1e5, maximum=1e5, doc="focal plane z, mm")
    field_points_deg: tuple[tuple[float, float], ...] = setting(
        doc="[[theta_x, theta_y], ...], deg, each within 10 deg of the axis")
    pupil: TmaPupilSettings = setting(doc="the off-axis pupil table [tma.pupil]")
    mirrors: tuple[TmaMirrorSettings, ...] = setting(doc="the mirrors [[tma.mirrors]] in light order")
    stop_z_mm: float = setting(0.0, minimum=-1e5, maximum=1e5, doc="stop plane z, mm")
    aligned_mirror: str = setting("M2", doc="the mirror on the hexapod")
    pivot_mm: tuple[float, float, float] | None = setting(None, minimum=-1e5, maximum=1e5,
                                                          doc="hexapod pivot (x, y, z) mm; absent: the vertex")
    camera_shape: tuple[int, int] = setting((128, 256), minimum=8, maximum=4096, doc="(H, W) camera pixels")
    pixel_mm: float = setting(1.0, minimum=1e-4, maximum=1e3, doc="stop-plane mm per camera pixel")
    as_built: TmaAsBuiltSettings = setting(TmaAsBuiltSettings(), doc="the as-built errors [tma.as_built]")


def parse_tma_config(document: Mapping[str, Any], *, source: str) -> tuple[TmaDesign, AsBuiltErrors]:
    """Build the design and the as-built errors from a parsed TOML document holding ``[tma]``.

    Raises
    ------
    ConfigError
        Missing ``[tma]``, any key error :func:`~wavestack.config.parse_section` reports, or an
        inconsistent design (too few mirrors, unknown aligned mirror, a pupil that does not fit
        the camera grid); each message names ``source`` and the key.
    """
    table = document.get("tma")
    if not isinstance(table, Mapping):
        raise ConfigError(f"{source}: missing table [tma] (the telescope design of the alignment bench)")
    settings = parse_section(TmaSettings, table, source=source, section="tma")
    try:
        pupil = PupilShape(settings.pupil.centre_mm, settings.pupil.size_mm, settings.pupil.corner_radius_mm)
        mirrors = tuple(TmaMirror(m.name, m.radius_mm, m.conic, m.vertex_z_mm) for m in settings.mirrors)
        design = TmaDesign(mirrors, settings.stop_z_mm, pupil, settings.image_z_mm, settings.field_points_deg,
                           settings.wavelength_nm, settings.aligned_mirror, settings.pivot_mm,
                           settings.camera_shape, settings.pixel_mm, settings.source)
    except ValueError as error:
        raise ConfigError(f"{source}: [tma] {error}") from None
    built = settings.as_built
    errors = AsBuiltErrors(built.decentre_mm_rms, built.despace_mm_rms, built.tilt_deg_rms, built.seed)
    return design, errors


def load_tma_config(path: str | Path) -> tuple[TmaDesign, AsBuiltErrors]:
    """Read ``[tma]`` from a TOML file (see :func:`parse_tma_config`)."""
    return parse_tma_config(load_toml(path), source=str(path))
