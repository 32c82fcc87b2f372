"""League throughput: end-to-end time-trial evaluations per hour with 1 and 2 workers.

A fresh SQLite league (or ``--database-url``) gets a 3-lap time trial on ``beginner_loop``;
lidar and camera models (hand-built ONNX graphs with random weights) are entered, each
entry queuing one job (models are uploaded and validated beforehand, entries made in a
burst), while real ``python -m league.worker`` processes (already started and idle) drain
the queue. Random-weight models never finish, so the event's time limit is
60 s of simulated time: 900 control steps, the length of 3 laps at the pure-pursuit bot's
pace (about 20 s a lap). Reported per case: evaluations per hour (entry of the first job
to the last result committed) and the queue latency from entry to leaderboard row (median
under load, and for a single entry into an idle league).

Run: ``.venv/bin/python benchmarks/league_throughput.py [--lidar-jobs 24 --camera-jobs 8]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import timedelta
from pathlib import Path

import numpy as np
from onnx import TensorProto, helper, numpy_helper
from rich.console import Console
from rich.table import Table
from sqlalchemy import func, select

from arena.actions import default_discrete_space
from league import crud
from league.db import make_engine, make_session_factory
from league.migrations import upgrade
from league.models import Entry, Event, Job, Model, Race, Racer, utcnow
from league.schemas import EventCreate
from league.settings import Settings
from league.storage import Storage
from submissions import pack, validate

ROOT = Path(__file__).resolve().parents[1]
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
        self.storage = Storage(self.settings.storage_dir)
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

    def workers(self, n: int) -> list[subprocess.Popen]:
        """Start ``n`` worker processes and wait until they are idle."""
        env = {**os.environ, "SLIPSTREAM_DATA_DIR": str(self.folder)}
        env["SLIPSTREAM_DATABASE_URL"] = self.settings.db_url
        env["SLIPSTREAM_POLL_SECONDS"] = "0.2"
        env |= {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
        procs = [
            subprocess.Popen(
                [sys.executable, "-m", "league.worker", "--name", f"bench{i}"],
                cwd=ROOT,
                env=env,
                stderr=subprocess.DEVNULL,
            )
            for i in range(n)
        ]
        time.sleep(4.0)
        return procs


def run_case(bench: Bench, sensor: str, jobs: int, workers: int) -> dict[str, float]:
    """Evaluations per hour and latencies for one sensor and worker count."""
    models = [bench.upload(sensor) for _ in range(jobs + 1)]
    procs = bench.workers(workers)
    try:
        since = bench.last_entry()
        bench.enter(models.pop())  # one entry into an idle league
        while bench.pending():
            time.sleep(0.05)
        idle = bench.latencies(since)[0]
        since = bench.last_entry()
        start = time.monotonic()
        for model_id in models:
            bench.enter(model_id)
        while bench.pending():
            time.sleep(0.05)
        elapsed = time.monotonic() - start
    finally:
        for proc in procs:
            proc.terminate()
            proc.wait()
    loaded = bench.latencies(since)
    return {
        "per_hour": jobs / elapsed * 3600,
        "seconds_per_eval": elapsed / jobs,
        "idle_latency": idle,
        "median_latency": statistics.median(loaded),
    }


def main() -> None:
    """Run every case and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lidar-jobs", type=int, default=16)
    parser.add_argument("--camera-jobs", type=int, default=8)
    parser.add_argument("--database-url", default=None)
    args = parser.parse_args()
    table = Table(title="Time-trial evaluations (3 laps' worth: 900 steps), beginner_loop")
    for column in ("model", "workers", "evals / hour", "s / eval", "idle latency s", "p50 s"):
        table.add_column(column, justify="right")
    with tempfile.TemporaryDirectory() as tmp:
        bench = Bench(Path(tmp), args.database_url)
        for sensor, jobs in (("lidar", args.lidar_jobs), ("camera", args.camera_jobs)):
            for workers in (1, 2):
                row = run_case(bench, sensor, jobs, workers)
                table.add_row(
                    sensor,
                    str(workers),
                    f"{row['per_hour']:.0f}",
                    f"{row['seconds_per_eval']:.2f}",
                    f"{row['idle_latency']:.2f}",
                    f"{row['median_latency']:.1f}",
                )
        bench.engine.dispose()
    Console().print(table)


if __name__ == "__main__":
    main()
