"""Where the real measured data live (``../shared/data`` beside the checkout).

``WAVESTACK_SHARED_DATA`` overrides the location. Tests that need the data skip when it is
absent on a developer's machine, but never under CI (``CI`` set): there a missing folder is a
failure, so a green CI always means the real-data tests ran.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

DATA = Path(os.environ.get("WAVESTACK_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


def require_shared_data() -> pytest.MarkDecorator:
    """A skip marker for tests that need the data, disabled under CI."""
    return pytest.mark.skipif(
        not DATA.is_dir() and not os.environ.get("CI"),
        reason=f"real data not found at {DATA} (set WAVESTACK_SHARED_DATA)",
    )
