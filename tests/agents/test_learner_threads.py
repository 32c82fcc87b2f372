"""The learner's torch threads step down to one while other processes crowd the cores."""

from __future__ import annotations

from agents.learner_threads import FIRST_RETRY, LAST_RETRY, LearnerThreads


def _crowded(threads: LearnerThreads) -> None:
    """One update that got half the CPU time its threads asked for (another process ran)."""
    threads.measured(wall_s=2.0, cpu_s=0.5 * 2.0 * threads.now)


def _alone(threads: LearnerThreads) -> None:
    threads.measured(wall_s=2.0, cpu_s=0.99 * 2.0 * threads.now)


def test_an_update_that_had_its_cores_keeps_every_thread() -> None:
    threads = LearnerThreads(2)
    for _ in range(10):
        _alone(threads)
    assert threads.now == 2


def test_a_crowded_update_leaves_one_thread_until_the_retry() -> None:
    threads = LearnerThreads(4)
    _crowded(threads)
    assert threads.now == 1
    for _ in range(FIRST_RETRY - 1):
        _alone(threads)  # one thread gets its core: still no reason to try all four yet
        assert threads.now == 1
    _alone(threads)
    assert threads.now == 4


def test_retries_that_are_still_crowded_wait_twice_as_long_up_to_the_cap() -> None:
    threads = LearnerThreads(2)
    waits = []
    for _ in range(6):
        _crowded(threads)
        wait = 0
        while threads.now == 1:
            _alone(threads)
            wait += 1
        waits.append(wait)
    assert waits == [min(FIRST_RETRY * 2**k, LAST_RETRY) for k in range(6)]
    _alone(threads)  # the crowd left: the next crowding starts from the first wait again
    _crowded(threads)
    assert threads.now == 1 and threads._wait == FIRST_RETRY


def test_short_updates_and_one_thread_are_left_alone() -> None:
    threads = LearnerThreads(2)
    threads.measured(wall_s=0.01, cpu_s=0.0)
    assert threads.now == 2
    single = LearnerThreads(1)
    _crowded(single)
    assert single.now == 1
