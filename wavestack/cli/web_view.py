"""``--web``: the live web view of ``run``, ``polish`` and ``align`` (options, start, the URL on stderr).

The server starts before any device opens, so a port in use or a refused address costs nothing,
and the page shows "waiting" while the devices come up. The URL goes to standard error as
``web view: http://HOST:PORT/`` (standard output stays the results). The page has no login, so
only a loopback address is served unless ``--allow-remote`` says otherwise.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from contextlib import ExitStack
from typing import ParamSpec

from wavestack.cli.bind import check_bind
from wavestack.pipeline import InputError
from wavestack.web import LiveFeed, WebViewServer

__all__ = ["add_web_arguments", "chain", "open_web_view"]

P = ParamSpec("P")


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port 0..65535 (0 = any free port), got {text!r}")
    return value


def add_web_arguments(parser: argparse.ArgumentParser) -> None:
    """``--web``, ``--web-host``, ``--web-port``, ``--allow-remote``."""
    group = parser.add_argument_group("live web view")
    group.add_argument("--web", action="store_true",
                       help="serve a live web view (map, numbers, history) and print its URL on stderr")
    group.add_argument("--web-host", default="127.0.0.1", metavar="HOST",
                       help="address of the web view (default 127.0.0.1; another needs --allow-remote)")
    group.add_argument("--web-port", type=_port, default=8765, metavar="P",
                       help="port of the web view (default 8765; 0 = any free port)")
    group.add_argument("--allow-remote", action="store_true",
                       help="allow --web-host to be a non-loopback address (the page has no login: anyone who "
                            "reaches the port sees the station)")


def open_web_view(args: argparse.Namespace, stack: ExitStack, title: str, *, ordering: str = "noll") -> LiveFeed | None:
    """Start the web view if ``--web`` was given; ``stack`` stops it (after the feed's end). None without ``--web``.

    Raises
    ------
    InputError
        A non-loopback ``--web-host`` without ``--allow-remote``, or an address that cannot be served.
    """
    if not args.web:
        return None
    try:
        check_bind(args.web_host, args.web_port, args.allow_remote, simulator="the web view",
                   protocol="the page (HTTP, no login)")
    except ValueError as error:
        raise InputError(f"--web-host {args.web_host}: {error}") from None
    feed = LiveFeed(title, ordering=ordering)
    server = WebViewServer(feed, host=args.web_host, port=args.web_port)
    try:
        server.start()
    except OSError as error:
        raise InputError(f"--web-port {args.web_port}: cannot serve the web view on {args.web_host}:{args.web_port}: "
                         f"{error.strerror or error}; pass --web-port 0 for any free port") from None
    stack.callback(server.stop)
    stack.callback(feed.end, "the command ended")  # runs first (last in): the stopped state goes out
    print(f"web view: {server.url}", file=sys.stderr, flush=True)
    return feed


def chain(first: Callable[P, None], second: Callable[P, None] | None) -> Callable[P, None]:
    """A callback that calls ``first``, then ``second`` when given, with the same arguments.

    Example
    -------
    >>> seen = []
    >>> chain(seen.append, lambda value: seen.append(value * 2))(1); seen
    [1, 2]
    """
    if second is None:
        return first

    def both(*args: P.args, **kwargs: P.kwargs) -> None:
        first(*args, **kwargs)
        second(*args, **kwargs)
    return both
