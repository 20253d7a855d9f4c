"""What a ``wavestack`` subcommand is: its name, help texts, options and handler, as one value."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class Command:
    """One subcommand; each command module declares one (``COMMAND``) and the parser registers it.

    Attributes
    ----------
    name : str
        The word on the command line (``run``, ``fit``, ...).
    help : str
        One line in ``wavestack --help``.
    description : str
        The paragraph of ``wavestack NAME --help``.
    add_arguments : callable
        Declares the command's options on its sub-parser.
    handler : callable
        ``handler(args, parser)`` runs the command and returns the exit status.
    subject : callable, optional
        ``subject(args)`` names the command's main input (a file, a configuration); an error
        message that does not start with an input of the command line gets it as a prefix, so
        that every one-line error names what it is about.
    """

    name: str
    help: str
    description: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    handler: Callable[[argparse.Namespace, argparse.ArgumentParser], int]
    subject: Callable[[argparse.Namespace], str] | None = None

    def register(self, commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
        """Add this command's sub-parser to ``commands``; returns it."""
        parser = commands.add_parser(self.name, help=self.help, description=self.description)
        self.add_arguments(parser)
        parser.set_defaults(handler=self.handler, subject=self.subject)
        return parser
