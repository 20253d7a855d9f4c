"""The leak fixture must catch what it promises to catch (run through pytest's own pytester)."""

from __future__ import annotations

import pytest

pytest_plugins = ["pytester"]


def _run_inner(pytester: pytest.Pytester, body: str) -> pytest.RunResult:
    pytester.makeconftest((__import__("pathlib").Path(__file__).parent / "conftest.py").read_text())
    pytester.makepyfile(body)
    return pytester.runpytest_inprocess("-p", "no:cacheprovider", "-q")


def test_fixture_fails_a_test_that_leaves_a_thread_running(pytester: pytest.Pytester) -> None:
    result = _run_inner(
        pytester,
        """
import threading
stop = threading.Event()
def test_leaks():
    threading.Thread(target=stop.wait, args=(5,), name="leaky-worker", daemon=True).start()
def test_cleanup():
    stop.set()
""",
    )
    # a failure in fixture teardown is reported as an error of the leaking test
    result.assert_outcomes(passed=2, errors=1)
    result.stdout.fnmatch_lines(["*threads still running: leaky-worker*"])


def test_fixture_fails_a_test_that_leaves_a_socket_open(pytester: pytest.Pytester) -> None:
    result = _run_inner(
        pytester,
        """
import socket
held = []
def test_leaks():
    held.append(socket.socket())
def test_cleanup():
    held.pop().close()
""",
    )
    # a failure in fixture teardown is reported as an error of the leaking test
    result.assert_outcomes(passed=2, errors=1)
    result.stdout.fnmatch_lines(["*socket(s) left open*"])


def test_fixture_passes_a_test_that_cleans_up(pytester: pytest.Pytester) -> None:
    result = _run_inner(
        pytester,
        """
import socket, threading
def test_clean():
    s = socket.socket(); s.close()
    t = threading.Thread(target=lambda: None); t.start(); t.join()
""",
    )
    result.assert_outcomes(passed=1)
