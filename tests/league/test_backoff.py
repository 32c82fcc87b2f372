"""The daemons' waits between polls and retries: backoff and a sleep a stop signal ends."""

from __future__ import annotations

import time
from types import SimpleNamespace

import pytest

from league.jobs import queue
from league.jobs.queue import Backoff, sleep_unless_stopped


def test_backoff_doubles_to_its_cap_and_resets() -> None:
    backoff = Backoff(cap=4.0)
    waits = [backoff.next() for _ in range(5)]
    for wait, nominal in zip(waits, [0.5, 1.0, 2.0, 4.0, 4.0], strict=True):
        assert 0.75 * nominal <= wait <= 1.25 * nominal
    backoff.reset()
    assert backoff.next() <= 1.25 * 0.5


def test_a_late_wake_up_ends_the_sleep_instead_of_raising(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A process descheduled between reading the clock and sleeping found the wait over
    by then; the worker crashed asking ``time.sleep`` for a negative time (CI, a loaded
    2-core VM, during a database outage)."""
    readings = iter([0.0, 0.25, 0.35, 0.5])  # 0.05 s left at the first check, then past it
    slept: list[float] = []
    clock = SimpleNamespace(monotonic=lambda: next(readings), sleep=slept.append)
    monkeypatch.setattr(queue, "time", clock)  # the queue module's clock only
    sleep_unless_stopped(0.3, lambda: False)
    assert slept and all(s >= 0.0 for s in slept)
    assert sum(slept) <= 0.3


def test_a_stop_ends_the_sleep_within_a_tick() -> None:
    calls = 0

    def stopping() -> bool:
        nonlocal calls
        calls += 1
        return calls > 1

    start = time.monotonic()
    sleep_unless_stopped(30.0, stopping, tick=0.05)
    assert time.monotonic() - start < 5.0
