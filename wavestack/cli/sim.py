"""``wavestack sim DEVICE``: run one simulated instrument on its real transport until stopped.

Each simulator prints exactly one line, flushed at once, saying where to connect (``pty /dev/pts/N``
or ``listening 127.0.0.1:PORT``), then serves until Ctrl-C or SIGTERM. Any serial or Modbus tool
can then talk to it, not only wavestack.
"""

from __future__ import annotations

import argparse
import sys
import threading
from collections.abc import Callable
from pathlib import Path

from wavestack.cli.command import Command
from wavestack.cli.signals import stop_on_signals


def add_sim_arguments(parser: argparse.ArgumentParser) -> None:
    """Subcommands of ``wavestack sim``, one per simulated device."""
    devices = parser.add_subparsers(dest="device", required=True, metavar="DEVICE")
    pzt = devices.add_parser("pzt", help="Thorlabs MDT693B piezo controller on a pseudo-terminal",
                             description="Serve the simulated MDT693B on a pseudo-terminal; prints 'pty PATH'.")
    pzt.add_argument("--config", type=Path, help="TOML with [pzt] and [pzt.simulator] (default: built in)")
    plc = devices.add_parser("plc", help="polishing-station PLC on Modbus/TCP",
                             description="Serve the simulated polishing-station PLC; prints 'listening HOST:PORT'.")
    plc.add_argument("--config", type=Path, help="TOML register map and model (default: built in)")
    plc.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    plc.add_argument("--port", type=int, default=0, help="TCP port; 0 picks a free one (default)")
    plc.add_argument("--allow-remote", action="store_true",
                     help="allow a non-loopback host (Modbus/TCP has no authentication)")
    plc.add_argument("--job-folder", type=Path,
                     help="run a polishing machine that takes its job files from this folder")
    hexapod = devices.add_parser("hexapod", help="PI C-887 hexapod controller on GCS 2.0 over TCP",
                                 description="Serve the simulated PI hexapod controller (GCS 2.0); "
                                             "prints 'listening HOST:PORT'.")
    hexapod.add_argument("--config", type=Path, help="TOML with [hexapod.simulator] (default: built in)")
    hexapod.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    hexapod.add_argument("--port", type=int, default=0, help="TCP port; 0 picks a free one (default)")
    hexapod.add_argument("--allow-remote", action="store_true",
                         help="allow a non-loopback host (GCS over TCP has no authentication)")
    gige = devices.add_parser("gige", help="GigE Vision camera (GVCP/GVSP on UDP) looking at the simulated optic",
                              description="Serve a simulated GigE Vision camera; prints 'listening HOST:PORT'. "
                                          "Port 3956 (GVCP's own) lets aravis' arv-tool find it.")
    gige.add_argument("--config", type=Path, help="station TOML with [optic] and [camera.simulator] (default: built in)")
    gige.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    gige.add_argument("--port", type=int, default=0, help="UDP port; 0 picks a free one (default), 3956 is GVCP's")
    gige.add_argument("--allow-remote", action="store_true",
                      help="allow a non-loopback host (GVCP has no authentication)")
    gige.add_argument("--vendor", help="serve a real camera's register map (flir-bfs, alvium-1800u, basler-ace-gige)")
    gige.add_argument("--vendor-xml", type=Path, help="that camera's GenApi XML file (with --vendor)")
    bench = devices.add_parser("align-bench", help="the TMA alignment bench: hexapod, field stage, camera, piezo",
                               description="Serve the simulated alignment bench as a real one's devices (PI "
                                           "hexapod and field stage on GCS over TCP, the camera's USB bus over "
                                           "TCP, the piezo on a pty) with the telescope coupled inside; prints "
                                           "one 'NAME listening HOST:PORT' (or 'piezo pty PATH') line per device.")
    bench.add_argument("--config", type=Path, help="alignment TOML (default: the shipped tma-alignment.toml)")
    bench.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    for name in ("hexapod", "field-stage", "camera"):
        bench.add_argument(f"--{name}-port", type=int, default=0, help=f"TCP port of the {name}; 0 picks a free one")
    bench.add_argument("--piezo-port", type=int, help="serve the piezo on this TCP port (socket://) instead of a pty")
    bench.add_argument("--seed", type=int, help="seed of the mount error (default: [align.simulator] seed)")
    bench.add_argument("--allow-remote", action="store_true",
                       help="allow a non-loopback host (GCS and the USB tunnel have no authentication)")


def _announce(line: str) -> None:
    print(line, flush=True)


def run_sim(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Run the chosen simulator until interrupted; returns the exit status."""
    stop = threading.Event()
    runner: Callable[[], None]
    if args.device == "pzt":
        from wavestack.cli.sim_pzt import run_pzt_simulator

        def runner() -> None:
            run_pzt_simulator(args.config, _announce, stop)
    elif args.device == "align-bench":
        from wavestack.cli.sim_align_bench import run_align_bench_simulator

        def runner() -> None:
            run_align_bench_simulator(args.config, args.host, (args.hexapod_port, args.field_stage_port,
                                                               args.camera_port), args.allow_remote, args.seed,
                                      _announce, stop, piezo_port=args.piezo_port)
    elif args.device == "gige":
        from wavestack.cli.sim_gige import run_gige_simulator

        def runner() -> None:
            run_gige_simulator(args.config, args.host, args.port, args.allow_remote, _announce, stop,
                               vendor=args.vendor, vendor_xml=args.vendor_xml)
    elif args.device == "hexapod":
        from wavestack.cli.sim_hexapod import run_hexapod_simulator

        def runner() -> None:
            run_hexapod_simulator(args.config, args.host, args.port, args.allow_remote, _announce, stop)
    else:
        from wavestack.cli.sim_plc import run_plc_simulator

        def runner() -> None:
            run_plc_simulator(args.config, args.host, args.port, args.allow_remote, _announce, stop,
                              job_folder=args.job_folder)
    with stop_on_signals(stop):
        runner()
    print(f"wavestack sim {args.device}: stopped", file=sys.stderr)
    return 0


COMMAND = Command(
    "sim",
    help="run a simulated instrument standalone (pzt, plc, hexapod, gige, align-bench)",
    description="Run one simulated instrument on its real transport until Ctrl-C or SIGTERM.",
    add_arguments=add_sim_arguments, handler=run_sim,
    subject=lambda args: str(args.config) if args.config else f"sim {args.device}",
)
