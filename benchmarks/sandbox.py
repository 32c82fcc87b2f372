"""Sandbox overheads: a child's round trip, and how soon the wall-clock limit kills it.

``round trip`` runs a child that answers at once (fork, limits, JSON over the pipe, wait);
``warm round trip`` sends the same request to a :class:`league.sandbox.WarmSandbox` child
that stays up between requests (limits per request, frames both ways); ``wall kill`` runs
a child that sleeps forever under a ``--wall`` second limit and reports how long after the
limit :func:`league.sandbox.run_limited` raised (the kill's lateness).
Imports the arena first, as a worker does, so the forked child is the size of a worker.

Run: ``.venv/bin/python benchmarks/sandbox.py [--runs N] [--wall SECONDS]``
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from rich.console import Console
from rich.table import Table

import arena  # noqa: F401  (a worker forks with the arena imported)
from league.sandbox import SandboxError, SandboxLimits, WarmSandbox, run_limited


def round_trips(runs: int) -> list[float]:
    """Seconds per ``run_limited`` of a child that answers at once."""
    limits = SandboxLimits(wall_seconds=30.0)
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        run_limited(lambda: {"laps": [1.5]}, limits)
        times.append(time.perf_counter() - start)
    return times


def warm_round_trips(runs: int) -> list[float]:
    """Seconds per request to a warm child that answers at once (its first one not counted)."""
    sandbox = WarmSandbox(lambda _: {"laps": [1.5]}, SandboxLimits(wall_seconds=30.0))
    sandbox.run(b"")
    times = []
    try:
        for _ in range(runs):
            start = time.perf_counter()
            sandbox.run(b"")
            times.append(time.perf_counter() - start)
    finally:
        sandbox.close()
    return times


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
    args = parser.parse_args()
    table = Table(title="Sandbox overheads")
    for col in ("case", "median ms", "max ms"):
        table.add_column(col, justify="left" if col == "case" else "right")
    kill_runs = max(1, args.runs // 4)
    for name, times in (
        ("round trip (answer at once)", round_trips(args.runs)),
        ("warm round trip (answer at once)", warm_round_trips(args.runs)),
        (f"wall kill, past the {args.wall:g} s limit", wall_kill_lateness(kill_runs, args.wall)),
    ):
        table.add_row(name, f"{1e3 * float(np.median(times)):.1f}", f"{1e3 * max(times):.1f}")
    console = Console(width=120)
    console.print(table)
    console.print(
        f"{args.runs} round trips, {kill_runs} kills; 1-min load average {os.getloadavg()[0]:.1f}"
    )


if __name__ == "__main__":
    main()
