"""The command line is built once from the commands' own declarations."""

from __future__ import annotations

import argparse

from wavestack.cli import COMMANDS, build_parser
from wavestack.cli.command import Command


def test_every_command_is_registered_once_in_order() -> None:
    assert [c.name for c in COMMANDS] == ["run", "replay", "fit", "analyze", "bench", "sim", "plc", "polish", "align",
                                          "batch", "calibrate"]
    parser = build_parser()
    (subparsers,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    assert list(subparsers.choices) == [c.name for c in COMMANDS]
    for command in COMMANDS:
        sub = subparsers.choices[command.name]
        assert sub.description == command.description and sub.get_default("handler") is command.handler


def test_a_command_registers_its_options_and_handler() -> None:
    seen: list[str] = []

    def handler(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
        seen.append(args.word)
        return 0

    command = Command("echo", help="say a word", description="Say one word.",
                      add_arguments=lambda p: p.add_argument("word"), handler=handler)
    parser = argparse.ArgumentParser(prog="t")
    command.register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["echo", "hello"])
    assert args.handler(args, parser) == 0 and seen == ["hello"]
