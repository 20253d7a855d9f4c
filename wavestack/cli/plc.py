"""``wavestack plc status|rearm``: the operator's look at the polishing PLC, and the re-arm after a trip.

Run while a station is running: the command opens a second Modbus/TCP connection as a *monitor*
(it never writes the heartbeat, which the station owns, and never sends a command). ``status``
prints one line: the PLC's state, and what the machine's panel shows (the display block: the
last result's validity, residual RMS, PVr and the drawing's verdict); ``rearm`` writes 1 to the PLC's re-arm register after a watchdog trip and prints
the status after it. A running station then sees the PLC healthy at its next heartbeat, reads back
what the machine holds (the watchdog zeroed the outputs), resets its safety stage to it and
re-arms its output on the next valid fresh result. This is the only way a trip is recovered once
a command was sent: the station never re-arms its own watchdog after start-up.

The PLC's address comes from ``--url tcp://HOST:PORT`` or from the ``[plc]`` table of a station
or PLC configuration (``--config F``); with both, the URL overrides the file's address. A station
on the simulated PLC (``sim://plc``) serves it on a free loopback port that ``wavestack -v run``
logs (``PLC simulator listening on 127.0.0.1:PORT``): pass it with ``--url``.
Exit status 0, 2 on bad input, 3 on a device error (no connection, no reply).
"""

from __future__ import annotations

import argparse
import logging
from dataclasses import replace
from pathlib import Path

from wavestack.cli.arguments import positive_float
from wavestack.cli.command import Command
from wavestack.config import load_plc_config
from wavestack.drivers.plc import PlcStatus, PolishingLink, ResultDisplay, SpecCode

__all__ = ["COMMAND", "describe_display", "describe_status", "run_plc"]


def add_plc_arguments(parser: argparse.ArgumentParser) -> None:
    """Subcommands of ``wavestack plc``."""
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    for name, help_text in (("status", "print the PLC's status in one line"),
                            ("rearm", "re-arm the PLC's watchdog after a trip, then print its status")):
        action = actions.add_parser(name, help=help_text, description=help_text + ".")
        action.add_argument("--config", type=Path, help="TOML with a [plc] table (default: built in)")
        action.add_argument("--url", help="the PLC's address, tcp://HOST:PORT (overrides the file's)")
        action.add_argument("--timeout", type=positive_float, default=2.0, help="seconds per exchange (default 2)")


def describe_status(status: PlcStatus) -> str:
    """One line for an operator: the state first, then the figures."""
    if status.watchdog_tripped:
        return "TRIPPED (watchdog; outputs zeroed): re-arm with `wavestack plc rearm`"
    state = ("E-STOP" if status.estop else "BUSY" if status.busy else "READY" if status.ready else "NOT READY")
    flags = [name for name, on in (("fault", status.fault), ("heartbeat seen", status.heartbeat_seen)) if on]
    return (f"{state}; last accepted command {status.last_accepted_id}, heartbeat echo {status.heartbeat_echo}, "
            f"status word {status.raw_word}" + (f" ({', '.join(flags)})" if flags else ""))


def describe_display(display: ResultDisplay) -> str:
    """The panel in a few words: ``"panel: result 12 valid, residual RMS 3.21 nm, PVr 45.6 nm, FAIL (limiting IRR)"``."""
    verdict = {SpecCode.NO_SPEC: "no spec", SpecCode.NOT_JUDGED: "not judged"}.get(
        display.spec, f"{display.spec.name} (limiting {display.limiting})")
    if not display.valid:
        return f"panel: result {display.result_index} INVALID, {verdict}"
    pvr = f", PVr {display.pvr_nm:.3g} nm" if display.pvr_nm is not None else ""
    return f"panel: result {display.result_index} valid, residual RMS {display.residual_rms_nm:.3g} nm{pvr}, {verdict}"


def _link(args: argparse.Namespace) -> PolishingLink:
    config = load_plc_config(args.config)
    settings = config.link
    if args.url is not None:
        settings = replace(settings, url=args.url)
    if settings.simulated:
        raise ValueError(f"{config.source}: [plc] url is sim://plc: the station's simulated PLC listens on a free "
                         "port; pass --url tcp://127.0.0.1:PORT (`wavestack -v run` logs the port)")
    host, port = settings.host, settings.port  # ValueError naming the URL when it is not tcp://HOST:PORT
    return PolishingLink(host, port, settings.register_map(), settings.link_timing(), monitor=True)


def run_plc(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Print the status, or re-arm and print it; DeviceError goes to the top level (exit 3)."""
    if not getattr(args, "verbose", False):  # pymodbus logs each refused connection: one line is ours
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    with _link(args) as link:
        status = link.connect(timeout_s=args.timeout)
        if args.action == "rearm":
            was_tripped = status.watchdog_tripped
            status = link.rearm(timeout_s=args.timeout)
            note = "re-armed" if was_tripped else "re-arm written (the watchdog was not tripped)"
            print(f"{link.device}: {note}; now {describe_status(status)}")
        else:
            display = None if status.watchdog_tripped else link.read_display(timeout_s=args.timeout)
            panel = "" if display is None else f"; {describe_display(display)}"
            print(f"{link.device}: {describe_status(status)}{panel}")
    return 0


COMMAND = Command(
    "plc",
    help="the polishing PLC's status, and its re-arm after a watchdog trip (status, rearm)",
    description="Talk to the polishing PLC as an operator while the station runs (a monitor connection: no "
                "heartbeat, no command). 'status' prints one line; 'rearm' re-arms a tripped watchdog.",
    add_arguments=add_plc_arguments, handler=run_plc,
)
