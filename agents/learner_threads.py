"""Torch threads for the learner: every core it may use, one while other processes hold them.

A multi-threaded torch op waits for all its threads at every step. When other processes
(another training, the league's races, a build) keep the cores busy, one of those threads
is often not scheduled and the others spin until it is: on a 2-core VM a camera update
took 1.5 s alone on two threads, 9 s beside another training on two, and 2.8 s on one
(benchmarks/RESULTS.md, "Training beside other work"). The process then gets about half
the CPU time its threads ask for, which is what :class:`LearnerThreads` watches: after an
update whose threads got less than :data:`SHARE_FLOOR` of the cores they asked for, the
learner goes on with one thread, and tries all of them again after :data:`FIRST_RETRY`
updates, twice as long after each try that is still crowded (up to :data:`LAST_RETRY`).

The thread count changes the order of torch's sums, so a run whose count changed is not
bit-for-bit the run on a quiet machine; an explicit ``--threads N`` is kept as given.
"""

from __future__ import annotations

SHARE_FLOOR = 0.75
"""The least share of ``threads x wall time`` the update's CPU time may be and still count
as having had its cores (alone: 0.98-0.99; beside another training: 0.49-0.50)."""
FIRST_RETRY = 4
LAST_RETRY = 64
MIN_WALL_S = 0.05
"""Updates shorter than this say nothing about the load (the share is mostly noise)."""


class LearnerThreads:
    """How many torch threads the next update runs on, at most ``most``."""

    def __init__(self, most: int) -> None:
        self.most = most
        self.now = most
        self._wait = 0  # updates left on one thread before the next try with `most`
        self._retry = FIRST_RETRY

    def measured(self, wall_s: float, cpu_s: float) -> None:
        """Account for an update that ran on :attr:`now` threads and got ``cpu_s`` seconds
        of this process's CPU time in ``wall_s`` seconds."""
        if self.most == 1 or wall_s < MIN_WALL_S:
            return
        if self.now == 1:
            self._wait -= 1
            if self._wait <= 0:
                self.now = self.most
            return
        if cpu_s >= SHARE_FLOOR * wall_s * self.now:
            self._retry = FIRST_RETRY
            return
        self.now, self._wait = 1, self._retry
        self._retry = min(2 * self._retry, LAST_RETRY)
