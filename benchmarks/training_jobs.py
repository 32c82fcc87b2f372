"""Training jobs on the league server: what they cost the API's reads, and what the sandbox
and the trainer cost training.

Three measurements on one data directory (SQLite), one table:

1. ``slipstream train`` alone, with the settings of the jobs below: samples/s.
2. The same settings as one training job on one trainer (``slipstream league trainer``,
   its child in the bubblewrap sandbox, the host to itself as ``slipstream train`` has):
   samples/s from the job's iterations.
3. API reads (``GET /api/events`` and a leaderboard) paced by wrk, pinned to the last core,
   with no training and then while two jobs train on two trainers (each given half the
   cores; kept off wrk's core unless ``--no-spare-load-core``, so that wrk times the
   server and not its own waits for a core): p50 and p99.

samples/s counts the iterations after the first (start-up apart), from the run's own
elapsed time, evaluations included. Needs wrk and bubblewrap.

    .venv/bin/python benchmarks/training_jobs.py --minutes 1.5
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
from api_load import PACER, wrk
from harness import ResultTable, add_record_option, start_league, write

from league import crud
from league.db import make_engine, make_session_factory
from league.migrations import upgrade
from league.schemas import EventCreate

OPTIONS = {"track": "slipstream_speedway", "sensors": "camera", "action_space": "default"}
REWARD = "follow_center_line"


def samples_per_second(rows: list[tuple[int, float]]) -> float:
    """Steps per second of ``(steps, elapsed_s)`` rows, the first iteration left out."""
    if len(rows) < 3:
        raise RuntimeError(f"too few iterations to measure ({len(rows)})")
    steps = sum(s for s, _ in rows[1:])
    return steps / (rows[-1][1] - rows[0][1])


def local_run(folder: Path, minutes: float, workers: int) -> float:
    """``slipstream train`` with the jobs' settings; its samples/s."""
    out = folder / "local-run"
    command = [sys.executable, "-m", "slipstream", "train", "--out", str(out)]
    command += ["--minutes", str(minutes), "--workers", str(workers), "--reward-fn", REWARD]
    for key, value in OPTIONS.items():
        command += [f"--{key.replace('_', '-')}", value]
    subprocess.run(command, check=True, capture_output=True)
    with (out / "metrics.csv").open() as handle:
        rows = [(int(r["steps"]), float(r["elapsed_s"])) for r in csv.DictReader(handle)]
    return samples_per_second(rows)


def job_rate(client: httpx.Client, job_id: int) -> float:
    """A finished job's samples/s, from its iterations."""
    metrics = client.get(f"/api/training-jobs/{job_id}/metrics").json()
    return samples_per_second([(m["steps"], m["elapsed_s"]) for m in metrics])


def submit(client: httpx.Client, minutes: float) -> int:
    """Queue one job with the benchmark's settings; its id."""
    from agents.rewards import bundled_samples

    body = {
        "name": "bench",
        "reward_source": bundled_samples()[REWARD].read_text(),
        "options": OPTIONS,
        "minutes": minutes,
    }
    answer = client.post("/api/training-jobs", json=body)
    answer.raise_for_status()
    return answer.json()["id"]


def wait_for(client: httpx.Client, job_ids: list[int], states: set[str], timeout: float) -> None:
    """Until every job's status is in ``states``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if all(client.get(f"/api/training-jobs/{j}").json()["status"] in states for j in job_ids):
            return
        time.sleep(1)
    raise RuntimeError(f"jobs {job_ids} did not reach {states} within {timeout:g} s")


def trainers(
    count: int, env: dict[str, str], cores: set[int] | None = None
) -> list[subprocess.Popen]:
    """Start ``count`` trainer processes (on ``cores`` only, when given)."""
    command = [sys.executable, "-m", "league", "trainer"]
    pin = None if cores is None else lambda: os.sched_setaffinity(0, cores)
    return [
        subprocess.Popen(
            command,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            preexec_fn=pin,
        )
        for _ in range(count)
    ]


def stop(processes: list[subprocess.Popen]) -> None:
    """SIGTERM each, then wait."""
    for process in processes:
        process.terminate()
    for process in processes:
        process.wait(60)


def reads(base: str, event: int, seconds: float, core: int, pacer: Path) -> list[str]:
    """p50 / p99 (ms) of each read, paced by wrk on ``core``."""
    cells = []
    for path in ("/api/events", f"/api/events/{event}/leaderboard"):
        run = wrk(base + path, 8, seconds, core, script=pacer)
        cells += [f"{run.p50_ms:.1f}", f"{run.p99_ms:.1f}"]
    return cells


def main() -> None:
    """Run the three measurements and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=1.5, help="budget of each run")
    parser.add_argument("--workers", type=int, default=1, help="env workers of each run")
    parser.add_argument("--seconds", type=float, default=15, help="length of each wrk run")
    parser.add_argument("--rate", type=float, default=100, help="paced reads per second")
    parser.add_argument(
        "--spare-load-core",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="keep the two jobs off wrk's core, so wrk times the server, not its own waits",
    )
    add_record_option(parser)
    args = parser.parse_args()
    core = (os.cpu_count() or 1) - 1
    table = ResultTable(
        "Training jobs on the league server",
        ["measurement", "samples/s", "events p50 ms", "events p99 ms", "board p50 ms",
         "board p99 ms"],
    )  # fmt: skip
    with tempfile.TemporaryDirectory() as folder:
        data = Path(folder) / "data"
        data.mkdir()
        env = os.environ | {
            "SLIPSTREAM_DATA_DIR": str(data),
            "SLIPSTREAM_RATE_LIMIT_PER_SECOND": "0",
            "SLIPSTREAM_TRAINING_JOBS_TOTAL": "2",
            "SLIPSTREAM_TRAINING_JOBS_PER_RACER": "2",
            "SLIPSTREAM_TRAINING_WORKERS": str(args.workers),
            "SLIPSTREAM_POLL_SECONDS": "0.5",
        }
        engine = make_engine(f"sqlite:///{data / 'league.db'}")
        upgrade(engine)
        with make_session_factory(engine)() as session:
            _racer, token = crud.create_racer(session, "bench")
            event = crud.create_event(session, EventCreate(name="Bench Cup"), None).id
        engine.dispose()
        pacer = Path(folder) / "pacer.lua"
        pacer.write_text(PACER % {"rate": args.rate})
        local = local_run(Path(folder), args.minutes, args.workers)
        table.add_row("slipstream train, alone", f"{local:.0f}", "", "", "", "")
        headers = {"Authorization": f"Bearer {token}"}
        with (
            start_league("--no-access-log", env=env) as server,
            httpx.Client(base_url=server.url, headers=headers, timeout=60) as client,
        ):
            table.add_row("API reads, idle", "", *reads(server.url, event, args.seconds,
                                                      core, pacer))  # fmt: skip
            one = submit(client, args.minutes)
            running = trainers(1, env | {"SLIPSTREAM_TRAINING_JOBS_TOTAL": "1"})  # as alone
            wait_for(client, [one], {"done", "stopped", "failed"}, args.minutes * 60 + 300)
            stop(running)
            table.add_row("one training job, alone", f"{job_rate(client, one):.0f}", *[""] * 4)
            two = [submit(client, args.minutes), submit(client, args.minutes)]
            others = set(range(core)) or None  # wrk's core stays the load generator's
            running = trainers(2, env, others if args.spare_load_core else None)
            wait_for(client, two, {"running"}, 120)
            time.sleep(20)  # both past start-up
            busy = reads(server.url, event, args.seconds, core, pacer)
            wait_for(client, two, {"done", "stopped", "failed"}, args.minutes * 60 + 300)
            stop(running)
            rates = "+".join(f"{job_rate(client, j):.0f}" for j in two)
            table.add_row("API reads, two jobs training", rates, *busy)
    table.notes.append(
        f"{args.workers} env worker(s) a run, {args.minutes:g} min budgets, camera on "
        f"slipstream_speedway, reward {REWARD}; wrk paced at {args.rate:g} req/s on core "
        f"{core}, 8 connections, {args.seconds:g} s a route; the two jobs "
        + ("kept off wrk's core." if args.spare_load_core else "on every core.")
    )
    write(table, args.record)


if __name__ == "__main__":
    main()
