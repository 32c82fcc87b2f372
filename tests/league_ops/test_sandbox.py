"""The sandbox's limits, exercised directly with child functions defined here.

A valid model file cannot sleep (no such operator), so the wall-clock limit is shown with a
child that sleeps; the model-file versions of the CPU and memory limits are in
``test_worker.py``. These run without a database.
"""

from __future__ import annotations

import os
import time

import pytest

from league.jobs.sandbox import SandboxError, SandboxLimits, run_limited

QUICK = SandboxLimits(memory_mb=256, cpu_seconds=2, wall_seconds=2.0)


def test_an_answer_comes_back_as_json() -> None:
    assert run_limited(lambda: {"laps": [1.5, 2.0]}, QUICK) == {"laps": [1.5, 2.0]}


def test_sleeping_forever_hits_the_wall_limit() -> None:
    """How soon after the limit the child dies is measured by ``benchmarks/sandbox.py``."""
    with pytest.raises(SandboxError, match="wall-time limit of 2 s") as err:
        run_limited(lambda: time.sleep(3600), QUICK)
    assert err.value.kind == "wall"


def test_spinning_hits_the_cpu_limit() -> None:
    def spin() -> None:
        while True:
            pass

    with pytest.raises(SandboxError, match="CPU-time limit of 1 s"):
        run_limited(spin, SandboxLimits(cpu_seconds=1, wall_seconds=10.0))


def test_allocating_gigabytes_hits_the_memory_limit() -> None:
    with pytest.raises(SandboxError, match="memory limit of 256 MiB") as err:
        run_limited(lambda: len(bytearray(4 * 1024**3)), QUICK)
    assert err.value.kind == "memory"


def test_errors_and_hard_crashes_are_reported() -> None:
    def boom() -> None:
        raise ValueError("bad ruleset")

    with pytest.raises(SandboxError, match="ValueError: bad ruleset"):
        run_limited(boom, QUICK)
    with pytest.raises(SandboxError, match="SIGABRT"):
        run_limited(os.abort, QUICK)


def test_a_failing_heartbeat_kills_the_child() -> None:
    def tick() -> None:
        raise RuntimeError("lease lost")

    with pytest.raises(RuntimeError, match="lease lost"):
        run_limited(lambda: time.sleep(3600), SandboxLimits(wall_seconds=30.0), tick)
