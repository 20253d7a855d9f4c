"""The role's thread: jobs one after another on one thread, a busy role's next job on its own, a clean close."""

from __future__ import annotations

import threading

import pytest

from wavestack.drivers.role_thread import RoleThread

TIMEOUT_S = 5.0


def test_jobs_run_one_after_another_on_the_same_thread() -> None:
    role = RoleThread("role-test")
    threads: list[threading.Thread] = []
    try:
        for _ in range(3):
            job = role.run(lambda: threads.append(threading.current_thread()))
            job.join(TIMEOUT_S)
            assert not job.is_alive()
    finally:
        role.close(TIMEOUT_S)
    assert len(threads) == 3 and len(set(threads)) == 1 and threads[0].name == "role-test"
    assert not threads[0].is_alive()  # closed


def test_a_job_submitted_while_the_last_one_runs_gets_a_thread_of_its_own() -> None:
    role = RoleThread("role-test")
    release, started = threading.Event(), threading.Event()
    seen: list[threading.Thread] = []

    def stuck() -> None:
        seen.append(threading.current_thread())
        started.set()
        release.wait(TIMEOUT_S)

    try:
        first = role.run(stuck)
        assert started.wait(TIMEOUT_S)
        second = role.run(lambda: seen.append(threading.current_thread()))
        second.join(TIMEOUT_S)  # not blocked by the stuck job
        assert not second.is_alive() and first.is_alive()
    finally:
        release.set()
        role.close(TIMEOUT_S)
    assert not first.is_alive() and len(seen) == 2 and seen[0] is not seen[1]


def test_an_exception_in_a_job_is_reported_and_the_role_goes_on(monkeypatch) -> None:
    caught: list[threading.ExceptHookArgs] = []
    monkeypatch.setattr(threading, "excepthook", caught.append)
    role = RoleThread("role-test")

    def fail() -> None:
        raise ValueError("job failed")

    try:
        role.run(fail).join(TIMEOUT_S)
        done = threading.Event()
        role.run(done.set).join(TIMEOUT_S)
    finally:
        role.close(TIMEOUT_S)
    assert done.is_set()
    assert [(a.exc_type, str(a.exc_value), a.thread.name) for a in caught] == [(ValueError, "job failed", "role-test")]


def test_run_after_close_raises_and_close_is_idempotent() -> None:
    role = RoleThread("role-test")
    role.close()  # never started: nothing to end
    with pytest.raises(RuntimeError, match="role-test"):
        role.run(lambda: None)
    role.close()
