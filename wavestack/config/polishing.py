"""A polishing station's configuration: a station file plus a ``[polishing]`` table.

``wavestack polish`` reads one TOML file: every table of a station file
(:mod:`wavestack.config.station`) and ``[polishing]`` with its sub-tables:

``[polishing]``
    :class:`PolishingSettings`: the target, the run budget, the solver, the measurement (results
    averaged, noise limit, freshness), the job-level limits (removal depth per run, total dwell),
    the wait for the machine, the optic's scale (``pixel_mm`` on the camera grid,
    ``reflection_factor``). Job files go to ``[plc] job_folder`` (the machine's share; a temporary
    folder when it is not set and the PLC is simulated).
``[polishing.tif]``
    :class:`TifSettings`: the host's model of the tool (Gaussian from FWHM and peak rate, or a
    measured TIF map file).
``[polishing.machine]``
    :class:`MachineSettings`: feed, acceleration, travel and dwell-per-point limits the program is
    planned and checked against.

``wavestack/config/polishing.toml`` beside this module is the simulated polishing station the
command runs without ``--config``. Every error is one :class:`ConfigError` line naming the file,
the table, the key and what was expected, as for the station's own tables.

The station's parser refuses tables it does not know, so the ``[polishing]`` tables are cut out
of the text before the rest is parsed as a station; the cut is checked by parsing both halves
(the station half must equal the whole document less ``polishing``), so a file the cut cannot
separate (a ``polishing.x = ...`` dotted key at the top level, a multi-line string holding a table
header) is refused with a line saying how to write it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from wavestack.config.schema import ConfigError, parse_section, parse_toml, read_config_text, setting
from wavestack.config.station import parse_station_config
from wavestack.config.station_schema import StationConfig

__all__ = ["DEFAULT_POLISHING_CONFIG", "MachineSettings", "PolishingConfig", "PolishingSettings", "TifSettings",
           "load_polishing_config", "parse_polishing_config"]

#: The simulated polishing station, shipped inside the package.
DEFAULT_POLISHING_CONFIG = Path(__file__).resolve().parent / "polishing.toml"
_HEADER = re.compile(r"^\s*\[\[?\s*([A-Za-z0-9_.\-\"' ]+?)\s*\]\]?\s*(#.*)?$")


@dataclass(frozen=True)
class TifSettings:
    """``[polishing.tif]``: the host's tool influence function."""

    kind: Literal["gaussian", "map"] = setting("gaussian", doc="a Gaussian from fwhm_mm, or a measured map file")
    fwhm_mm: float = setting(4.0, minimum=0.01, maximum=1000.0, doc="Gaussian TIF full width at half maximum, mm")
    peak_rate_nm_s: float = setting(10.0, minimum=1e-6, maximum=1e6, doc="peak removal rate, nm/s")
    file: str | None = setting(None, doc="kind = 'map': a .npy removal-rate map, nm/s, on the camera's pixel grid")

    def __post_init__(self) -> None:
        if self.kind == "map" and not self.file:
            raise ValueError("kind = 'map' needs file (a .npy removal-rate map, nm/s)")


@dataclass(frozen=True)
class MachineSettings:
    """``[polishing.machine]``: what the host plans and checks a program against (machine frame, mm)."""

    max_feed_mm_s: float = setting(50.0, minimum=1e-3, maximum=1e4, doc="largest feed between dwell points, mm/s")
    max_accel_mm_s2: float = setting(500.0, minimum=1e-3, maximum=1e6, doc="largest acceleration, mm/s^2")
    travel_x_mm: tuple[float, float] = setting((-80.0, 80.0), minimum=-1e5, maximum=1e5, doc="x travel [lo, hi], mm")
    travel_y_mm: tuple[float, float] = setting((-80.0, 80.0), minimum=-1e5, maximum=1e5, doc="y travel [lo, hi], mm")
    max_dwell_per_point_s: float = setting(60.0, minimum=1e-3, maximum=1e5, doc="longest dwell at one point, s")
    path: Literal["raster", "spiral"] = setting("raster", doc="the order the tool visits the dwell points")
    step_px: int = setting(4, minimum=1, maximum=64, doc="dwell points every step_px camera pixels each way")

    def __post_init__(self) -> None:
        for name in ("travel_x_mm", "travel_y_mm"):
            lo, hi = getattr(self, name)
            if not lo < hi:
                raise ValueError(f"{name}: expected [lo, hi] with lo < hi, got [{lo:g}, {hi:g}]")


@dataclass(frozen=True)
class PolishingSettings:
    """``[polishing]``: the closed loop (module notes)."""

    target_rms_nm: float = setting(5.0, minimum=0.0, maximum=1e5, doc="stop once the surface RMS is at most this, nm")
    max_runs: int = setting(4, minimum=1, maximum=1000, doc="most polishing runs (jobs) in one campaign")
    solver: Literal["fft", "lsq", "bounded"] = setting(
        "fft", doc="dwell solver: RIFTA FFT inverse filter, constrained LSQ, or bounded LSQ with FFT operators")
    averaged_results: int = setting(8, minimum=2, maximum=1000, doc="valid live results averaged per measurement")
    max_results_per_measurement: int = setting(64, minimum=2, maximum=100000,
                                               doc="results looked at before a measurement gives up")
    max_noise_rms_nm: float = setting(2.0, minimum=0.0, maximum=1e5,
                                      doc="a noisier average is not trusted (standard error, nm RMS)")
    min_improvement: float = setting(0.0, minimum=0.0, maximum=0.99,
                                     doc="fraction of the RMS a run must remove, else the loop stops")
    max_removal_nm_per_run: float = setting(500.0, minimum=1e-3, maximum=1e6,
                                            doc="deepest removal one job may plan anywhere, nm")
    max_total_dwell_s: float = setting(3600.0, minimum=1e-3, maximum=1e7, doc="longest total dwell of one job, s")
    freshness_s: float = setting(60.0, minimum=0.1, maximum=1e5,
                                 doc="a measurement older than this when its job starts is not used, s")
    done_timeout_s: float = setting(600.0, minimum=1.0, maximum=1e6,
                                    doc="longest wait for the machine's done, wall-clock s")
    pixel_mm: float = setting(0.25, minimum=1e-4, maximum=100.0, doc="camera pixel size on the optic, mm")
    edge_px: int = setting(2, minimum=0, maximum=64,
                           doc="pixels taken off the measured aperture's rim (its phase is the noisiest)")
    reflection_factor: float = setting(2.0, minimum=0.1, maximum=10.0,
                                       doc="wavefront per surface (2: reflection at normal incidence)")
    tif_rate_uncertainty: float = setting(0.03, minimum=0.0, maximum=1.0,
                                          doc="how far the real tool's removal rate may be from the model (fraction)")
    tif_width_uncertainty: float = setting(0.03, minimum=0.0, maximum=1.0,
                                           doc="how far the real tool's width may be from the model (fraction)")
    efficiency_spread: float = setting(0.02, minimum=0.0, maximum=1.0,
                                       doc="per-point removal efficiency spread, 1 +- this (uniform)")
    process_noise_nm: float = setting(0.2, minimum=0.0, maximum=1e4, doc="process noise a job leaves, nm RMS")
    floor_tolerance: float = setting(0.1, minimum=0.0, maximum=10.0,
                                     doc="stop at the floor once the RMS is within this fraction above it")
    target_figure: str | None = setting(None, doc="a .npy map of the target surface, nm, subtracted (else PTT only)")
    tif: TifSettings = field(default_factory=TifSettings)
    machine: MachineSettings = field(default_factory=MachineSettings)


@dataclass(frozen=True, eq=False)
class PolishingConfig:
    """A checked polishing configuration: the station and the loop.

    Attributes
    ----------
    source : str
        The file (or a name for text).
    text : str
        The whole file, as read (recorded with a campaign).
    station : StationConfig
        Every station table (its ``text`` is the file less the ``[polishing]`` tables).
    polishing : PolishingSettings
    """

    source: str
    text: str
    station: StationConfig
    polishing: PolishingSettings

    def resolve(self, name: str | None) -> Path | None:
        """A file named in the configuration, relative to the configuration's folder."""
        if name is None:
            return None
        path = Path(name).expanduser()
        return path if path.is_absolute() else Path(self.source).resolve().parent / path


def _split_polishing(text: str, source: str) -> tuple[str, dict[str, Any]]:
    """(station text, the [polishing] table) of a polishing file (module notes)."""
    document = parse_toml(text, source)
    if "polishing" not in document:
        raise ConfigError(f"{source}: missing table [polishing] (the closed loop's settings)")
    kept: list[str] = []
    inside = False
    for line in text.splitlines(keepends=True):
        header = _HEADER.match(line)
        if header is not None:
            name = header.group(1).replace('"', "").replace("'", "").replace(" ", "")
            inside = name == "polishing" or name.startswith("polishing.")
        if not inside:
            kept.append(line)
    station_text = "".join(kept)
    rest = {k: v for k, v in document.items() if k != "polishing"}
    try:
        separated = parse_toml(station_text, source) == rest
    except ConfigError:
        separated = False
    if not separated:
        raise ConfigError(f"{source}: cannot separate the [polishing] tables from the station's; expected them "
                          "written as [polishing] and [polishing.*] table headers")
    return station_text, document["polishing"]


def parse_polishing_config(text: str, *, source: str) -> PolishingConfig:
    """Check a polishing configuration given as TOML text.

    Raises
    ------
    ConfigError
        Any error of a station table (:func:`~wavestack.config.station.parse_station_config`), of
        ``[polishing]``, or a station the loop cannot use: not an interferometer, a
        ``fit_decimation`` other than 1 (the loop measures on the camera's pixel grid).
    """
    station_text, table = _split_polishing(text, source)
    station = parse_station_config(station_text, source=source)
    polishing = parse_section(PolishingSettings, table, source=source, section="polishing")
    if station.station.kind != "interferometer":
        raise ConfigError(f"{source}: [station] kind = {station.station.kind!r}: the polishing loop needs an "
                          "interferometer station (surface maps)")
    if station.processing.fit_decimation != 1:
        raise ConfigError(f"{source}: [processing] fit_decimation = {station.processing.fit_decimation}: the "
                          "polishing loop measures on the camera's pixel grid; expected 1")
    if station.plc is None:
        raise ConfigError(f"{source}: missing table [plc]: the polishing loop hands its jobs to the machine's PLC")
    _check_simulated_surface(station, polishing, source)
    return PolishingConfig(source=source, text=text, station=station, polishing=polishing)


def _check_simulated_surface(station: StationConfig, polishing: PolishingSettings, source: str) -> None:
    """A simulated optic's surface is on the grid the loop assumes: same pixel size, same reflection factor."""
    surface = getattr(station.optic, "surface", None) if station.camera.simulated else None
    if surface is None:
        return
    for key in ("pixel_mm", "reflection_factor"):
        simulated, assumed = getattr(surface, key), getattr(polishing, key)
        if simulated != assumed:
            raise ConfigError(f"{source}: [polishing] {key} = {assumed:g} differs from the simulated optic's "
                              f"[optic.surface] {key} = {simulated:g}; expected the same")


def load_polishing_config(path: str | Path | None = None) -> PolishingConfig:
    """Read and check a polishing file (None: the packaged ``polishing.toml``, the simulated station)."""
    path = DEFAULT_POLISHING_CONFIG if path is None else Path(path)
    return parse_polishing_config(read_config_text(path), source=str(path))
