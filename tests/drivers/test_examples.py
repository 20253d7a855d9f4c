"""The Examples sections of the device faces run as doctests."""

from __future__ import annotations

import doctest
from types import ModuleType

import pytest

from wavestack.drivers import link, safety
from wavestack.drivers.genicam import formula, node_map, registers
from wavestack.drivers.gige import discovery
from wavestack.drivers.mdt693b import command_sets, protocol
from wavestack.drivers.plc import codec, gate


@pytest.mark.parametrize("module", [link, safety, codec, gate, protocol, command_sets, formula, node_map, registers,
                                    discovery], ids=lambda m: m.__name__)
def test_examples_run(module: ModuleType) -> None:
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0, f"{module.__name__} has no Examples to run"
    assert result.failed == 0
