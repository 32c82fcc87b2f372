"""The garage's catalogue on a busy host: how long its first build takes while other
processes keep every core busy, as training jobs do.

Starts a fresh ``python -m league serve`` for each run, then ``--hogs`` processes that spin
(each its own process: they stand for a training job's workers), and times the first
``GET /api/garage/catalogue``: the build of every built-in track's racing line, in the
server's thread pool. One row per number of hogs: median and worst of ``--runs`` fresh
servers. ``--tree PATH`` serves another checkout (an older commit in a worktree), to
compare.

    .venv/bin/python benchmarks/catalogue_under_load.py --hogs 0,4,8 --runs 3
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import tempfile
import time
from pathlib import Path

import httpx
from harness import ROOT, ResultTable, add_record_option, spin, start_league, summary, write


def first_catalogue_seconds(tree: Path, hogs: int) -> float:
    """Seconds a fresh server of ``tree`` takes to answer its first catalogue while
    ``hogs`` spinning processes run."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    with (
        tempfile.TemporaryDirectory(prefix="catalogue-load-") as data_dir,
        start_league("--data-dir", data_dir, "--no-access-log", env=env, cwd=tree) as server,
    ):
        spinners = [multiprocessing.Process(target=spin, daemon=True) for _ in range(hogs)]
        for process in spinners:
            process.start()
        try:
            start = time.perf_counter()
            answer = httpx.get(f"{server.url}/api/garage/catalogue", timeout=600.0)
            answer.raise_for_status()
            return time.perf_counter() - start
        finally:
            for process in spinners:
                process.kill()
                process.join()


def main() -> None:
    """Parse the options, time each row, write the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hogs", default="0,4,8", help="numbers of spinning processes")
    parser.add_argument("--runs", type=int, default=3, help="fresh servers per row")
    parser.add_argument("--tree", type=Path, default=ROOT, help="the checkout to serve")
    add_record_option(parser)
    args = parser.parse_args()
    table = ResultTable(
        f"First catalogue build on a busy host ({os.cpu_count()} cores)",
        ("spinning processes", "runs", "median s", "worst s"),
    )
    for hogs in (int(n) for n in args.hogs.split(",")):
        times = summary([first_catalogue_seconds(args.tree, hogs) for _ in range(args.runs)])
        table.add_row(hogs, times.n, f"{times.median:.2f}", f"{times.max:.2f}")
    if args.tree.resolve() != ROOT:
        table.notes.append(f"served from {args.tree}")
    write(table, args.record)


if __name__ == "__main__":
    main()
