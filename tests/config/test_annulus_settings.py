"""``[processing] fit_method = "annulus"`` and its ``obscuration``: parsed, checked, and built by the station."""

from __future__ import annotations

import re

import numpy as np
import pytest

from wavestack.config import DEFAULT_CONFIG
from wavestack.config.schema import ConfigError
from wavestack.config.station import parse_station_config
from wavestack.pipeline import Aperture, SyncFitterSource

DEFAULT_TEXT = DEFAULT_CONFIG.read_text(encoding="utf-8")
SOURCE = "annulus.toml"


def _processing(**lines: str) -> str:
    """The default station with ``fit_method`` replaced and keys added to ``[processing]``."""
    text = re.sub(r'(?m)^fit_method = "csf-qcm".*$', "", DEFAULT_TEXT)
    added = "\n".join(f"{key} = {value}" for key, value in lines.items())
    return text.replace("[processing]\n", f"[processing]\n{added}\n", 1)


def _ring() -> np.ndarray:
    rows, cols = np.indices((80, 80), dtype=float)
    r = np.hypot(rows - 39.5, cols - 40.0)
    return (r <= 36.0) & (r >= 12.0)


@pytest.mark.parametrize("given", [None, 0.25])
def test_the_station_builds_annulus_fitters_with_the_configured_obscuration(given) -> None:
    extra = {} if given is None else {"obscuration": repr(given)}
    config = parse_station_config(_processing(fit_method='"annulus"', **extra), source=SOURCE)
    settings = config.processing.fit_settings()
    assert settings.method == "annulus" and settings.obscuration == given
    choice = SyncFitterSource(settings).new_aperture(Aperture.from_mask(_ring()))  # replay's synchronous builds
    assert choice.kind == "annulus" and not choice.fallback
    basis = choice.fitter.basis
    if given is None:  # measured: the nearest ring pixel centre, about 12 px of about 36
        assert choice.fitter.diagnostics.obscuration_source == "measured"
        assert basis.annular_obscuration == pytest.approx(12.0 / 36.0, abs=1.0 / 36.0)
    else:
        assert basis.annular_obscuration == given and choice.fitter.diagnostics.obscuration_source == "given"


@pytest.mark.parametrize(("lines", "expected"), [
    ({"fit_method": '"circle"', "obscuration": "0.3"},
     r'\[processing\] obscuration = 0.3: expected only with fit_method = "annulus" \(fit_method is \'circle\'\)'),
    ({"fit_method": '"annulus"', "obscuration": "0.0"},
     r"\[processing\] obscuration = 0.0: expected a ratio of inner to outer radius strictly between 0 and 1"),
    ({"fit_method": '"annulus"', "obscuration": "1.0"}, r"strictly between 0 and 1"),
    ({"fit_method": '"annulus"', "obscuration": "1.5"}, r"obscuration"),
])
def test_an_obscuration_that_cannot_work_is_refused_in_one_line(lines, expected) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_station_config(_processing(**lines), source=SOURCE)
    message = str(caught.value)
    assert message.startswith(f"{SOURCE}: ") and "\n" not in message
    assert re.search(expected, message), message
