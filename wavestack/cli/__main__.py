"""``python -m wavestack.cli``: the command line."""

from __future__ import annotations

import sys

from wavestack.cli import main

sys.exit(main())
