"""Load test of the league API: leaderboard and race endpoints at several concurrencies.

Seeds a database (SQLite in a temp folder, or a fresh PostgreSQL schema) with an event of
``--racers`` racers and their races, starts ``slipstream league`` in a subprocess (one
uvicorn worker), and drives it from this process with asyncio + httpx. Prints a Markdown
table of p50 / p99 latency and throughput. On a 2-core machine client and server share
the cores, so the figures are a floor.

    .venv/bin/python benchmarks/api_load.py --backend sqlite --seconds 5
    .venv/bin/python benchmarks/api_load.py --backend postgres \
        --postgres-url postgresql+psycopg://postgres@127.0.0.1:5432/test
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

from arena.config import RaceConfig
from arena.race import CarResult, RaceResult
from league import crud
from league.db import make_engine, make_session_factory, scratch_schema
from league.migrations import upgrade
from league.models import Entry, Model
from league.schemas import EventCreate
from league.storage import Storage

ROOT = Path(__file__).resolve().parents[1]


def seed(url: str, data_dir: Path, racers: int, races_each: int) -> tuple[int, int]:
    """Fill the database; return the event id and one race id."""
    engine = make_engine(url)
    upgrade(engine)
    storage = Storage(data_dir / "files")
    with make_session_factory(engine)() as session:
        event = crud.create_event(session, EventCreate(name="Load Cup", seeds=[0]), None)
        config = RaceConfig.build(**event.ruleset, cars=[{"name": "car0"}])
        race_id = 0
        for i in range(racers):
            racer, _ = crud.create_racer(session, f"racer{i:04d}")
            model = Model(owner_id=racer.id, name=f"m{i}", sha256=f"{i:064x}", size=1, info={})
            session.add(model)
            session.commit()
            entry = Entry(event_id=event.id, model_id=model.id, racer_id=racer.id)
            session.add(entry)
            session.commit()
            for r in range(races_each):
                laps = [9.0 + (i * 7 + r * 3) % 17 / 10.0 for _ in range(3)]
                car = CarResult(
                    "car0", "finished", 3, laps, min(laps), sum(laps) / 3, sum(laps),
                    i % 3, 0, 0, 0.0, 60.0, 1,
                )  # fmt: skip
                trace = {"car0": {"t": [k / 15 for k in range(450)], "x": [0.0] * 450}}
                result = RaceResult(config, [car], ["car0"], 30.0, 450, trace)
                race_id = crud.record_race(session, storage, event, result, {"car0": entry}).id
        event_id = event.id
    engine.dispose()
    return event_id, race_id


def start_server(url: str, data_dir: Path, port: int) -> subprocess.Popen:
    """Run the league server (no rate limit) and wait until it answers."""
    env = {
        **os.environ,
        "SLIPSTREAM_DATA_DIR": str(data_dir),
        "SLIPSTREAM_DATABASE_URL": url,
        "SLIPSTREAM_RATE_LIMIT_PER_SECOND": "0",
    }
    code = (
        "import uvicorn; from league.app import create_app; "
        f"uvicorn.run(create_app(), host='127.0.0.1', port={port}, "
        "log_level='warning', access_log=False)"
    )
    proc = subprocess.Popen([sys.executable, "-c", code], env=env, cwd=ROOT)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/readyz").status_code == 200:
                return proc
        except httpx.TransportError:
            time.sleep(0.1)
    proc.kill()
    raise RuntimeError("server did not start")


async def drive(base: str, path: str, clients: int, seconds: float) -> tuple[list[float], int]:
    """``clients`` concurrent loops on ``path`` for ``seconds``; latencies (s) and errors."""
    latencies: list[float] = []
    errors = 0
    limits = httpx.Limits(max_connections=clients, max_keepalive_connections=clients)
    async with httpx.AsyncClient(base_url=base, limits=limits, timeout=30) as client:
        deadline = time.perf_counter() + seconds

        async def loop() -> None:
            nonlocal errors
            while time.perf_counter() < deadline:
                start = time.perf_counter()
                response = await client.get(path)
                latencies.append(time.perf_counter() - start)
                errors += response.status_code != 200

        await asyncio.gather(*(loop() for _ in range(clients)))
    return latencies, errors


def percentile(values: list[float], q: float) -> float:
    """The q-quantile (0-1) of ``values``."""
    return statistics.quantiles(values, n=1000, method="inclusive")[int(q * 1000) - 1]


def run_backend(name: str, url: str, args: argparse.Namespace, port: int) -> list[str]:
    """Seed, serve and measure one backend; Markdown table rows."""
    with tempfile.TemporaryDirectory() as folder:
        data_dir = Path(folder)
        event_id, race_id = seed(url, data_dir, args.racers, args.races)
        proc = start_server(url, data_dir, port)
        rows = []
        try:
            base = f"http://127.0.0.1:{port}"
            paths = {
                "leaderboard": f"/api/events/{event_id}/leaderboard",
                "race": f"/api/races/{race_id}",
                "races list": f"/api/races?event={event_id}&limit=20",
            }
            for label, path in paths.items():
                asyncio.run(drive(base, path, 4, 0.5))  # warm up
                for clients in args.clients:
                    lat, errors = asyncio.run(drive(base, path, clients, args.seconds))
                    rows.append(
                        f"| {name} | {label} | {clients} | {len(lat) / args.seconds:.0f} | "
                        f"{percentile(lat, 0.5) * 1000:.1f} | {percentile(lat, 0.99) * 1000:.1f}"
                        f" | {errors} |"
                    )
                    print(rows[-1], flush=True)
        finally:
            proc.terminate()
            proc.wait(timeout=10)
    return rows


def main() -> None:
    """Parse options, run the chosen backends, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backend", choices=["sqlite", "postgres", "both"], default="both")
    parser.add_argument(
        "--postgres-url",
        default=os.environ.get("SLIPSTREAM_TEST_POSTGRES_URL"),
        help="PostgreSQL URL (default: $SLIPSTREAM_TEST_POSTGRES_URL)",
    )
    parser.add_argument("--clients", type=int, nargs="+", default=[1, 16, 64])
    parser.add_argument("--seconds", type=float, default=5.0, help="per measurement")
    parser.add_argument("--racers", type=int, default=50)
    parser.add_argument("--races", type=int, default=3, help="races per racer")
    parser.add_argument("--port", type=int, default=8765)
    args = parser.parse_args()
    header = [
        "| backend | endpoint | clients | req/s | p50 ms | p99 ms | errors |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    print("\n".join(header), flush=True)
    rows = []
    if args.backend in ("sqlite", "both"):
        with tempfile.TemporaryDirectory() as folder:
            rows += run_backend("sqlite", f"sqlite:///{folder}/league.db", args, args.port)
    if args.backend in ("postgres", "both"):
        if not args.postgres_url:
            print("postgres skipped: give --postgres-url or set SLIPSTREAM_TEST_POSTGRES_URL")
        else:
            url, drop = scratch_schema(args.postgres_url, "league_bench")
            try:
                rows += run_backend("postgres", url, args, args.port + 1)
            finally:
                drop()
    print("\n" + "\n".join(header + rows))


if __name__ == "__main__":
    main()
