"""Sandbox overheads: a child's round trip, and how soon the wall-clock limit kills it.

``round trip`` runs a child that answers at once (fork, limits, JSON over the pipe, wait);
``warm round trip`` sends the same request to a :class:`league.jobs.sandbox.WarmSandbox` child
that stays up between requests (limits per request, frames both ways); ``wall kill`` runs
a child that sleeps forever under a ``--wall`` second limit and reports how long after the
limit :func:`league.jobs.sandbox.run_limited` raised (the kill's lateness).
Imports the arena first, as a worker does, so the forked child is the size of a worker.

Run: ``.venv/bin/python benchmarks/sandbox.py [--runs N] [--wall SECONDS]``
"""

from __future__ import annotations

import argparse
import time

from harness import ResultTable, add_record_option, summary, time_calls, write

import arena  # noqa: F401  (a worker forks with the arena imported)
from league.jobs.sandbox import SandboxError, SandboxLimits, WarmSandbox, run_limited


def round_trips(runs: int) -> list[float]:
    """Seconds per ``run_limited`` of a child that answers at once."""
    limits = SandboxLimits(wall_seconds=30.0)
    return time_calls(lambda: run_limited(lambda: {"laps": [1.5]}, limits), runs)


def warm_round_trips(runs: int) -> list[float]:
    """Seconds per request to a warm child that answers at once (its first one not counted)."""
    sandbox = WarmSandbox(lambda _: {"laps": [1.5]}, SandboxLimits(wall_seconds=30.0))
    try:
        return time_calls(lambda: sandbox.run(b""), runs, warmup=1)
    finally:
        sandbox.close()


def wall_kill_lateness(runs: int, wall: float) -> list[float]:
    """Seconds past ``wall`` until a sleeping child's wall-time error came back."""
    limits = SandboxLimits(wall_seconds=wall)
    late = []
    for _ in range(runs):
        start = time.perf_counter()
        try:
            run_limited(lambda: time.sleep(3600), limits)
        except SandboxError as err:
            assert err.kind == "wall", err
        else:
            raise AssertionError("the sleeping child was not stopped")
        late.append(time.perf_counter() - start - wall)
    return late


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20, help="runs per case")
    parser.add_argument("--wall", type=float, default=1.0, help="wall limit of the kill case, s")
    add_record_option(parser)
    args = parser.parse_args()
    table = ResultTable("Sandbox overheads", ("case", "median ms", "max ms"))
    kill_runs = max(1, args.runs // 4)
    for name, times in (
        ("round trip (answer at once)", round_trips(args.runs)),
        ("warm round trip (answer at once)", warm_round_trips(args.runs)),
        (f"wall kill, past the {args.wall:g} s limit", wall_kill_lateness(kill_runs, args.wall)),
    ):
        stats = summary(times)
        table.add_row(name, f"{1e3 * stats.median:.1f}", f"{1e3 * stats.max:.1f}")
    table.notes.append(f"{args.runs} round trips, {kill_runs} kills")
    write(table, args.record)


if __name__ == "__main__":
    main()
