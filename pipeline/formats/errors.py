"""The one error every file reader raises."""

from __future__ import annotations


class InputError(ValueError):
    """A file that cannot be used: missing, unreadable, or not of the expected kind.

    Its message names the file and what was expected, so that a command line can print it as
    one line.
    """
