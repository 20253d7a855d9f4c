"""Fixtures of the fault suite (the harness itself is :mod:`station.faults.harness`)."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest


@pytest.fixture
def thread_errors(monkeypatch) -> Iterator[list[threading.ExceptHookArgs]]:
    """Exceptions that escaped any thread during the test; the test fails if there are any."""
    caught: list[threading.ExceptHookArgs] = []
    monkeypatch.setattr(threading, "excepthook", caught.append)
    yield caught
    assert not caught, [f"{a.thread.name if a.thread else '?'}: {a.exc_type.__name__}: {a.exc_value}" for a in caught]
