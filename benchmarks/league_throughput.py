"""League throughput: end-to-end time-trial evaluations per hour with 1 and 2 workers.

A fresh SQLite league (or ``--database-url``) gets a 3-lap time trial on ``beginner_loop``;
lidar and camera models (hand-built ONNX graphs with random weights) are entered, each
entry queuing one job (models are uploaded and validated beforehand, entries made in a
burst), while real ``python -m league.jobs.worker`` processes (already started and idle) drain
the queue. Random-weight models never finish, so the event's time limit is
60 s of simulated time: 900 control steps, the length of 3 laps at the pure-pursuit bot's
pace (about 20 s a lap). Reported per case: evaluations per hour (entry of the first job
to the last result committed), the CPU seconds the workers and their race children spent
per evaluation (what load on a shared machine does not change) and the queue latency from
entry to leaderboard row (median under load, and for a single entry into an idle league).

``--profile`` splits one evaluation into its phases instead, in CPU milliseconds, run in
this process the way a worker runs them (the phases the warm sandbox removed are listed
too). ``--quick`` is a short run: 2 workers only, few jobs.

Run: ``.venv/bin/python benchmarks/league_throughput.py [--lidar-jobs 24 --camera-jobs 8]``
``[--quick] [--profile]``
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from datetime import timedelta
from pathlib import Path
from typing import Any

import numpy as np
from harness import ROOT, ResultTable, add_record_option, summary, write
from onnx import TensorProto, helper, numpy_helper
from sqlalchemy import func, select

from arena.actions import default_discrete_space
from arena.camera import CameraRenderer
from arena.config import resolve_track
from arena.env import RacingEnv
from arena.race import RaceResult, run_race
from league import crud
from league.db import make_engine, make_session_factory
from league.jobs.evaluation import build_plan, decode_plan, encode_plan, policies
from league.jobs.queue import lease_job
from league.jobs.sandbox import SandboxLimits, WarmSandbox, run_limited
from league.jobs.worker import race_answer, record_result
from league.migrations import upgrade
from league.models import Entry, Event, Job, Model, Race, Racer, utcnow
from league.schemas import EventCreate
from league.settings import Settings
from league.store.local import LocalFileStore
from submissions import load_policy, pack, validate

RACES = 5
"""Races per measured race phase in ``--profile`` (the least CPU time counts)."""
LIMITS = SandboxLimits()
N_ACTIONS = default_discrete_space().n


def _graph(nodes: list, name: str, shape: list, dtype: int, inits: list) -> bytes:
    graph = helper.make_graph(
        nodes,
        "policy",
        [helper.make_tensor_value_info(name, dtype, ["batch", *shape])],
        [helper.make_tensor_value_info("out", TensorProto.FLOAT, ["batch", N_ACTIONS])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    return model.SerializeToString()


def lidar_onnx(seed: int) -> bytes:
    """A lidar MLP 64 -> 64 -> N logits with random weights."""
    rng = np.random.default_rng(seed)
    inits = [
        numpy_helper.from_array(rng.normal(size=(64, 64)).astype(np.float32), "w1"),
        numpy_helper.from_array(np.zeros(64, np.float32), "b1"),
        numpy_helper.from_array(rng.normal(size=(64, N_ACTIONS)).astype(np.float32), "w2"),
        numpy_helper.from_array(np.zeros(N_ACTIONS, np.float32), "b2"),
    ]
    nodes = [
        helper.make_node("Gemm", ["lidar", "w1", "b1"], ["h"]),
        helper.make_node("Relu", ["h"], ["r"]),
        helper.make_node("Gemm", ["r", "w2", "b2"], ["out"]),
    ]
    return _graph(nodes, "lidar", [64], TensorProto.FLOAT, inits)


def camera_onnx(seed: int) -> bytes:
    """A small camera CNN: uint8 120x160 -> conv 8x8/4 (16) -> conv 4x4/2 (32) -> N logits."""
    rng = np.random.default_rng(seed)
    inits = [
        numpy_helper.from_array(np.array(1 / 255, np.float32), "scale"),
        numpy_helper.from_array(rng.normal(0, 0.1, (16, 1, 8, 8)).astype(np.float32), "k1"),
        numpy_helper.from_array(rng.normal(0, 0.1, (32, 16, 4, 4)).astype(np.float32), "k2"),
        numpy_helper.from_array(rng.normal(size=(32, N_ACTIONS)).astype(np.float32), "w"),
        numpy_helper.from_array(np.zeros(N_ACTIONS, np.float32), "b"),
    ]
    nodes = [
        helper.make_node("Cast", ["camera"], ["f"], to=TensorProto.FLOAT),
        helper.make_node("Mul", ["f", "scale"], ["x"]),
        helper.make_node("Transpose", ["x"], ["nchw"], perm=[0, 3, 1, 2]),
        helper.make_node("Conv", ["nchw", "k1"], ["c1"], strides=[4, 4]),
        helper.make_node("Relu", ["c1"], ["r1"]),
        helper.make_node("Conv", ["r1", "k2"], ["c2"], strides=[2, 2]),
        helper.make_node("Relu", ["c2"], ["r2"]),
        helper.make_node("GlobalAveragePool", ["r2"], ["g"]),
        helper.make_node("Flatten", ["g"], ["flat"]),
        helper.make_node("Gemm", ["flat", "w", "b"], ["out"]),
    ]
    return _graph(nodes, "camera", [120, 160, 1], TensorProto.UINT8, inits)


class Bench:
    """A league on disk, its event, and worker processes."""

    def __init__(self, folder: Path, url: str | None) -> None:
        self.settings = Settings(data_dir=folder, database_url=url, poll_seconds=0.2)
        self.engine = make_engine(self.settings.db_url)
        upgrade(self.engine)
        self.sessions = make_session_factory(self.engine)
        self.storage = LocalFileStore(self.settings.storage_dir)
        self.folder = folder
        opens = utcnow() - timedelta(minutes=1)
        spec = EventCreate(name="Bench", laps=3, time_limit_s=60.0, seeds=[0], opens_at=opens)
        with self.sessions() as session:
            self.event = crud.create_event(session, spec, None)
            self.owner = crud.create_racer(session, "bench")[0]
        self.count = 0

    def upload(self, sensor: str) -> int:
        """Store a fresh model (new weights); its id."""
        self.count += 1
        graph = lidar_onnx(self.count) if sensor == "lidar" else camera_onnx(self.count)
        path = self.folder / f"m{self.count}.zip"
        pack(path, graph, default_discrete_space(), [sensor])
        data = path.read_bytes()
        info = validate(data).info
        with self.sessions() as session:
            owner = session.get_one(Racer, self.owner.id)
            return crud.add_model(session, self.storage, owner, path.stem, data, info)[0].id

    def enter(self, model_id: int) -> None:
        """Enter a stored model: one job."""
        with self.sessions() as session:
            event = session.get_one(Event, self.event.id)
            crud.enter_model(session, event, session.get_one(Model, model_id), utcnow())

    def pending(self) -> int:
        """Jobs not finished yet."""
        with self.sessions() as session:
            return session.scalar(
                select(func.count(Job.id)).where(Job.status.in_(("queued", "running")))
            )

    def latencies(self, since: int) -> list[float]:
        """Seconds from entry to race row for entries after id ``since``."""
        with self.sessions() as session:
            rows = session.execute(
                select(Entry.created_at, Race.created_at)
                .join(Job, Job.entry_id == Entry.id)
                .join(Race, Race.job_id == Job.id)
                .where(Entry.id > since)
            ).all()
        return [(done - entered).total_seconds() for entered, done in rows]

    def last_entry(self) -> int:
        """The newest entry id (0 if none)."""
        with self.sessions() as session:
            return session.scalar(select(func.max(Entry.id))) or 0

    def workers(self, n: int, tree: Path = ROOT) -> list[subprocess.Popen]:
        """Start ``n`` worker processes of ``tree`` (default: this checkout; an older one
        measures its code on the same data) and wait until they are idle."""
        env = {**os.environ, "SLIPSTREAM_DATA_DIR": str(self.folder), "PYTHONPATH": str(tree)}
        env["SLIPSTREAM_DATABASE_URL"] = self.settings.db_url
        env["SLIPSTREAM_POLL_SECONDS"] = "0.2"
        env |= {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
        procs = [
            subprocess.Popen(
                [sys.executable, "-m", "league.jobs.worker", "--name", f"bench{i}"],
                cwd=tree,
                env=env,
                stderr=subprocess.DEVNULL,
            )
            for i in range(n)
        ]
        time.sleep(4.0)
        return procs


def _cpu_seconds(pid: int) -> float:
    """CPU time of a live process and of its children: reaped ones and (one level) live ones."""
    tick = os.sysconf("SC_CLK_TCK")
    with open(f"/proc/{pid}/stat") as handle:
        fields = handle.read().rsplit(")", 1)[1].split()
    total = sum(int(f) for f in fields[11:15]) / tick  # utime stime cutime cstime
    with open(f"/proc/{pid}/task/{pid}/children") as handle:
        for child in handle.read().split():
            with contextlib.suppress(OSError):  # gone meanwhile: in cutime now, or lost (rare)
                total += _cpu_seconds(int(child))
    return total


def _stop(proc: subprocess.Popen) -> float:
    """SIGTERM a worker, reap it; its CPU seconds and its reaped children's."""
    proc.terminate()
    _, _, usage = os.wait4(proc.pid, 0)
    proc.returncode = 0
    return usage.ru_utime + usage.ru_stime


def run_case(
    bench: Bench, sensor: str, jobs: int, workers: int, tree: Path = ROOT
) -> dict[str, float]:
    """Evaluations per hour, CPU per evaluation and latencies for one sensor and worker count
    (workers of ``tree``)."""
    models = [bench.upload(sensor) for _ in range(jobs + 1)]
    procs = bench.workers(workers, tree)
    cpu = 0.0
    try:
        since = bench.last_entry()
        bench.enter(models.pop())  # one entry into an idle league
        while bench.pending():
            time.sleep(0.05)
        idle = bench.latencies(since)[0]
        since = bench.last_entry()
        cpu = -sum(_cpu_seconds(proc.pid) for proc in procs)
        start = time.monotonic()
        for model_id in models:
            bench.enter(model_id)
        while bench.pending():
            time.sleep(0.05)
        elapsed = time.monotonic() - start
    finally:
        cpu += sum(_stop(proc) for proc in procs)  # idle polling until the stop is in it too
    loaded = bench.latencies(since)
    return {
        "per_hour": jobs / elapsed * 3600,
        "seconds_per_eval": elapsed / jobs,
        "cpu_per_eval": cpu / jobs,
        "idle_latency": idle,
        "median_latency": summary(loaded).median,
    }


def _cpu_ms(action: Callable[[], Any], repeats: int = 3) -> tuple[float, Any]:
    """Least CPU milliseconds of this process and its reaped children over ``repeats`` calls
    of ``action()``, and its last result."""

    def now() -> float:
        own, kids = (
            resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
        )
        return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime

    best, result = float("inf"), None
    for _ in range(repeats):
        start = now()
        result = action()
        best = min(best, 1000 * (now() - start))
    return best, result


def _warm_ms(handler: Callable[[bytes], object], request: bytes, runs: int) -> list[float]:
    """CPU ms of each of ``runs`` requests to a warm child, worker's and child's (the child's
    first request is not counted; the child's share is in clock ticks)."""
    sandbox = WarmSandbox(handler, LIMITS, max_runs=runs + 2)
    times = []
    try:
        sandbox.run(request)
        assert sandbox.pid is not None
        for _ in range(runs):
            child = _cpu_seconds(sandbox.pid)
            ms, _ = _cpu_ms(lambda: sandbox.run(request), 1)
            times.append(ms + 1000 * (_cpu_seconds(sandbox.pid) - child))
    finally:
        sandbox.close()
    return times


def profile(bench: Bench, sensor: str) -> list[tuple[str, float, str]]:
    """CPU ms of each phase of one evaluation (phase, ms, note), as a worker runs it."""
    bench.enter(bench.upload(sensor))
    with bench.sessions() as session:
        job = session.scalars(select(Job).order_by(Job.id.desc())).first()
        plan_ms, plan = _cpu_ms(lambda: build_plan(session, bench.storage, job))
    (car,) = plan.cars
    config = plan.config
    track = resolve_track(config)[0]
    request = encode_plan(plan)
    drivers = policies(plan)

    def fresh_env() -> None:
        env = RacingEnv(config)
        env.reset(seed=config.seed)
        env.close()

    env_ms = _cpu_ms(fresh_env)[0]
    bare_ms = _cpu_ms(lambda: run_race(config, drivers, record_trace=False), RACES)[0]
    race_ms, result = _cpu_ms(lambda: run_race(config, drivers, record_trace=True), RACES)
    text = json.dumps(result.to_dict(), separators=(",", ":")).encode()
    json_ms = _cpu_ms(lambda: RaceResult.from_dict(json.loads(json.dumps(result.to_dict()))))[0]
    with bench.sessions() as session:
        lease = lease_job(session, "profile", 60.0)
    assert lease is not None
    names = {car.name: car.entry_id}
    with bench.sessions() as session:
        record = _cpu_ms(lambda: record_result(session, bench.storage, lease, result, names), 1)
    fork_ms = _cpu_ms(lambda: run_limited(lambda: None, LIMITS), 10)[0]
    fresh_race_ms = _cpu_ms(lambda: run_limited(lambda: race_answer(plan), LIMITS), RACES)[0]
    warm_race_ms = min(_warm_ms(lambda r: race_answer(decode_plan(r)), request, RACES))
    stored_ms = _cpu_ms(lambda: load_policy(car.model, non_finite="raise", run_policy=False))[0]
    full_ms = _cpu_ms(lambda: load_policy(car.model, non_finite="raise"))[0]
    camera_ms = _cpu_ms(lambda: CameraRenderer(track))[0] if sensor == "camera" else 0.0
    return [
        ("build the plan (database, model sha256)", plan_ms, "worker"),
        (
            "plan to the warm child and back (pipe)",
            summary(_warm_ms(lambda r: None, request, 50)).mean,
            "both",
        ),
        ("load the model: static checks + session", stored_ms, "child"),
        ("env build: physics world, cars, grid", env_ms, "child, every race"),
        (f"racing: {result.steps} control steps", bare_ms - env_ms, "child"),
        ("trace recording (record_trace=True)", race_ms - bare_ms, "child"),
        ("answer JSON: encode, decode, from_dict", json_ms, f"{len(text) // 1024} KiB"),
        ("record the result (DB, trace file)", record[0], "worker"),
        ("-- removed: fork per race", fork_ms, "now once per child"),
        (
            "-- removed: copy-on-write, first race",
            fresh_race_ms - warm_race_ms - fork_ms,
            "once per child",
        ),
        ("-- removed: behaviour re-validation", full_ms - stored_ms, "done at upload"),
        ("-- removed: camera renderer build", camera_ms, "once per track and child"),
    ]


def main() -> None:
    """Run every case and write the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lidar-jobs", type=int, default=16)
    parser.add_argument("--camera-jobs", type=int, default=8)
    parser.add_argument("--database-url", default=None)
    parser.add_argument("--quick", action="store_true", help="2 workers only, 8 + 4 jobs")
    parser.add_argument("--profile", action="store_true", help="phases of one evaluation")
    parser.add_argument(
        "--worker-path",
        type=Path,
        default=ROOT,
        help="run the workers of another checkout (e.g. a git worktree of an older commit)",
    )
    add_record_option(parser)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        bench = Bench(Path(tmp), args.database_url)
        table = phase_profile(bench) if args.profile else throughput(bench, args)
        bench.engine.dispose()
    write(table, args.record)


def phase_profile(bench: Bench) -> ResultTable:
    """The per-phase table of one lidar and one camera evaluation."""
    table = ResultTable(
        "One evaluation, CPU ms per phase (900 steps, beginner_loop)",
        ("phase", "lidar ms", "camera ms", "where"),
        "lrrl",
    )
    lidar, camera = profile(bench, "lidar"), profile(bench, "camera")
    for (phase, ms, where), (_, cam_ms, _) in zip(lidar, camera, strict=True):
        table.add_row(phase, f"{ms:.1f}", f"{cam_ms:.1f}", where)
    now = [
        sum(ms for phase, ms, _ in rows if not phase.startswith("--")) for rows in (lidar, camera)
    ]
    table.add_row("one evaluation now (sum)", f"{now[0]:.0f}", f"{now[1]:.0f}", "")
    return table


def throughput(bench: Bench, args: argparse.Namespace) -> ResultTable:
    """Run every case; the table."""
    columns = ("model", "workers", "evals / hour", "s / eval", "CPU s / eval", "idle latency s")
    table = ResultTable(
        "Time-trial evaluations (3 laps' worth: 900 steps), beginner_loop",
        (*columns, "p50 s"),
        "r" * (len(columns) + 1),
    )
    jobs = {"lidar": args.lidar_jobs, "camera": args.camera_jobs}
    if args.quick:
        jobs = {"lidar": 8, "camera": 4}
    for sensor, count in jobs.items():
        for workers in (2,) if args.quick else (1, 2):
            row = run_case(bench, sensor, count, workers, args.worker_path.resolve())
            table.add_row(
                sensor,
                str(workers),
                f"{row['per_hour']:.0f}",
                f"{row['seconds_per_eval']:.2f}",
                f"{row['cpu_per_eval']:.2f}",
                f"{row['idle_latency']:.2f}",
                f"{row['median_latency']:.1f}",
            )
    return table


if __name__ == "__main__":
    main()
