"""Training on a host that is busy with other work: seconds an iteration alone and beside
another training or spinning processes.

Each row runs ``slipstream train --recipe time_trial --track slipstream_speedway
--iterations N`` (camera, 2 env workers, the learner's auto threads unless ``--threads``)
from ``--tree`` and reads its ``metrics.csv`` and TensorBoard events: seconds an iteration
after the first ``SKIP`` (the start and first evaluations), seconds an update, and the
torch threads the updates ran on. Row "training" starts a second copy of the same command
(another seed and folder) at the same moment and reports the first; row "spinN" starts N
processes that keep a core busy each.

    .venv/bin/python benchmarks/train_beside_load.py --beside none,training,spin2
"""

from __future__ import annotations

import argparse
import csv
import multiprocessing
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from harness import ROOT, ResultTable, add_record_option, spin, write
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

SKIP = 4


def train_command(out: Path, seed: int, iterations: int, threads: int | None) -> list[str]:
    """The measured training's command line."""
    command = [sys.executable, "-m", "slipstream", "train", "--recipe", "time_trial"]
    command += ["--track", "slipstream_speedway", "--iterations", str(iterations)]
    command += ["--seed", str(seed), "--out", str(out)]
    return command + ([] if threads is None else ["--threads", str(threads)])


def read_run(out: Path) -> dict[str, float | str]:
    """Seconds an iteration and an update after the first ``SKIP``; the update threads."""
    with (out / "metrics.csv").open() as f:
        elapsed = [float(row["elapsed_s"]) for row in csv.DictReader(f)]
    events = EventAccumulator(str(out / "tensorboard"))
    events.Reload()
    tags = events.Tags()["scalars"]
    updates = [e.value for e in events.Scalars("Perf/learning_time")][SKIP:]
    threads = (
        sorted({int(e.value) for e in events.Scalars("Perf/update_threads")[SKIP:]})
        if "Perf/update_threads" in tags
        else []
    )
    return {
        "s_per_it": (elapsed[-1] - elapsed[SKIP - 1]) / (len(elapsed) - SKIP),
        "update_s": statistics.median(updates),
        "threads": "/".join(map(str, threads)) or "(not logged)",
    }


def measure(
    tree: Path, beside: str, iterations: int, threads: int | None
) -> dict[str, float | str]:
    """Run the measured training with ``beside`` (none, training or spinN) and read it."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    with tempfile.TemporaryDirectory(prefix="train-load-") as tmp:
        runs = [Path(tmp) / "measured"]
        spinners = []
        if beside == "training":
            runs.append(Path(tmp) / "other")
        elif beside.startswith("spin"):
            spinners = [multiprocessing.Process(target=spin, daemon=True) for _ in
                        range(int(beside.removeprefix("spin")))]  # fmt: skip
        for process in spinners:
            process.start()
        try:
            trainings = [
                subprocess.Popen(
                    train_command(out, seed, iterations, threads),
                    cwd=tree,
                    env=env,
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                )
                for seed, out in enumerate(runs, start=1)
            ]
            for training in trainings:
                if training.wait() != 0:
                    raise SystemExit(f"training failed (exit {training.returncode}) in {tree}")
        finally:
            for process in spinners:
                process.kill()
                process.join()
        return read_run(runs[0])


def main() -> None:
    """Parse the options, run each row, write the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--beside", default="none,training,spin2", help="rows: none, "
                        "training or spinN, comma-separated")  # fmt: skip
    parser.add_argument("--iterations", type=int, default=15)
    parser.add_argument("--threads", type=int, default=None, help="--threads of the trainings")
    parser.add_argument("--tree", type=Path, default=ROOT, help="the checkout to train with")
    add_record_option(parser)
    args = parser.parse_args()
    table = ResultTable(
        f"time_trial training, camera, 2 workers, its {SKIP + 1}-{args.iterations}",
        ("beside", "s/iteration", "update s (median)", "update threads"),
    )
    for beside in args.beside.split(","):
        run = measure(args.tree, beside, args.iterations, args.threads)
        table.add_row(beside, f"{run['s_per_it']:.2f}", f"{run['update_s']:.2f}", run["threads"])
    table.notes.append(f"--threads {args.threads or 'auto'}")
    if args.tree.resolve() != ROOT:
        table.notes.append(f"trained from {args.tree}")
    write(table, args.record)


if __name__ == "__main__":
    main()
