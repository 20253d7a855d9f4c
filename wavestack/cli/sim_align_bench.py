"""``wavestack sim align-bench``: the alignment bench as a real bench's devices, served until stopped.

From an alignment TOML (default: the shipped ``tma-alignment.toml``) it starts the PI hexapod and
field-stage simulators (GCS 2.0 over TCP), the station's simulated USB3 Vision camera (its USB bus
served over TCP, ``usbtcp://``) and MDT693B piezo (a pseudo-terminal), with the as-built telescope
and a seeded mount error of the secondary coupled inside
(:class:`~wavestack.simulators.align_bench_remote.RemoteAlignBench`), and prints one line per
device::

    hexapod listening 127.0.0.1:PORT
    field_stage listening 127.0.0.1:PORT
    camera listening 127.0.0.1:PORT usbtcp://127.0.0.1:PORT/SERIAL
    piezo pty /dev/pts/N                    (with --piezo-port: piezo listening 127.0.0.1:PORT socket://...)

``wavestack align`` with ``[align] simulated = false`` and those addresses in its configuration
(``config/tma-alignment-remote.toml``) then aligns it from another process, as a real bench.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path

from wavestack.cli.bind import check_bind
from wavestack.config.align import AlignConfig, load_align_config
from wavestack.config.station import load_station_config
from wavestack.pipeline import InputError
from wavestack.pipeline.telescope import HexapodPose
from wavestack.simulated import align_bench, simulated_interferometer
from wavestack.simulators.align_bench import SurfaceCoupling
from wavestack.simulators.align_bench_remote import RemoteAlignBench

__all__ = ["announcements", "open_remote_bench", "run_align_bench_simulator"]

_log = logging.getLogger(__name__)
_STOP_POLL_S = 0.1


def open_remote_bench(config: AlignConfig, stack: ExitStack, *, host: str = "127.0.0.1",
                      ports: tuple[int, int, int] = (0, 0, 0), piezo_port: int | None = None,
                      mount: HexapodPose | None = None, seed: int | None = None) -> RemoteAlignBench:
    """Build and start the remote bench an alignment configuration describes; ``stack`` stops it.

    Parameters
    ----------
    config : AlignConfig
        ``[tma]``, ``[tma.as_built]``, ``[align.simulator]``, ``[hexapod.simulator]``,
        ``[field_stage.simulator]`` and ``[align] station`` (a ``sim://u3v`` station file whose
        optic has a surface on the TMA's camera grid).
    host, ports
        Where the hexapod, the field stage and the camera's USB bus listen (0: free ports).
    piezo_port : int, optional
        Serve the piezo on TCP (``socket://``) at this port (0: a free one) instead of a pty.
    mount : HexapodPose, optional
        The secondary's mount error (default: drawn from ``[align.simulator]`` with ``seed``).
    seed : int, optional
        Overrides ``[align.simulator] seed``.

    Raises
    ------
    InputError
        No ``[align] station``, or one that is not a simulated interferometer with a surface.
    """
    station_path = config.station_path()
    if station_path is None:
        raise InputError(f"{config.source}: [align] station: required by the alignment-bench simulator "
                         "(the simulated camera, piezo and optic it serves)")
    station = load_station_config(station_path)
    if not station.camera.simulated or station.station.kind != "interferometer":
        raise InputError(f"{station_path}: [camera] url: expected sim://u3v and an interferometer station "
                         "(the bench serves the simulated camera itself)")
    bench = align_bench(config, mount=mount, seed=seed, host=host, hexapod_port=ports[0], field_stage_port=ports[1])
    interferometer, piezo = simulated_interferometer(station)
    surface = getattr(interferometer.optic, "surface", None)
    reflection = getattr(getattr(station.optic, "surface", None), "reflection_factor", 2.0)
    try:
        coupling = SurfaceCoupling(bench, surface, station.station.wavelength_nm, reflection,
                                   null_tilt=config.align.null_tilt)
    except ValueError as error:
        raise InputError(f"{station_path}: [optic.surface]: {error}") from None
    remote = RemoteAlignBench(bench, interferometer, piezo, coupling, host=host, camera_port=ports[2],
                              piezo_port=piezo_port)
    stack.enter_context(remote)
    _log.info("align bench: mount error %s (unknown to the host)", bench.truth.mount.as_tuple())
    return remote


def announcements(remote: RemoteAlignBench, host: str) -> list[str]:
    """The lines ``sim align-bench`` prints, one per device."""
    serial = remote.interferometer.camera.settings.serial
    lines = [f"hexapod listening {host}:{remote.bench.hexapod.port}",
             f"field_stage listening {host}:{remote.bench.field_stage.port}",
             f"camera listening {host}:{remote.usb.port} usbtcp://{host}:{remote.usb.port}/{serial}"]
    if remote.piezo_pty is not None:
        lines.append(f"piezo pty {remote.piezo_pty.port_path}")
    if remote.piezo_tcp is not None:
        lines.append(f"piezo listening {host}:{remote.piezo_tcp.port} socket://{host}:{remote.piezo_tcp.port}")
    return lines


def run_align_bench_simulator(config_path: Path | None, host: str, ports: tuple[int, int, int], allow_remote: bool,
                              seed: int | None, announce: Callable[[str], None], stop: threading.Event, *,
                              piezo_port: int | None = None) -> None:
    """Serve the bench until ``stop`` is set (module notes).

    Raises
    ------
    ValueError
        A non-loopback host without ``allow_remote``, a bad port, or a port the servers cannot bind.
    ConfigError, InputError
        A bad configuration.
    """
    for port in (*ports, *(() if piezo_port is None else (piezo_port,))):
        check_bind(host, port, allow_remote, simulator="the alignment bench", protocol="GCS and USB over TCP")
    config = load_align_config(config_path)
    with ExitStack() as stack:
        try:
            remote = open_remote_bench(config, stack, host=host, ports=ports, piezo_port=piezo_port, seed=seed)
        except OSError as error:
            raise ValueError(f"cannot serve the alignment bench on {host}: {error}") from None
        for line in announcements(remote, host):
            announce(line)
        while not stop.wait(_STOP_POLL_S):
            pass
    _log.info("alignment bench on %s stopped", host)
