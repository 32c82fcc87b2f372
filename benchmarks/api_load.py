"""Load test of the league's public reads with ``wrk``, a compiled load generator.

Needs Debian's wrk (``apt-get install wrk``). Prepares a league like the demo's (its four
events, the first filled with ``--racers`` racers and their races), starts
``slipstream league serve`` (``python -m league serve``, rate limit off, access log off)
pinned to one core and runs wrk pinned to another, then prints one table, a row per route:
throughput and p50 / p99 latency at 16 and 64 connections, and p50 / p99 at a fixed
``--rate`` (default 500 req/s).

Fixed rate: wrk has no rate option (wrk2 is not in Debian), so a small Lua script paces it.
Its ``delay()`` hands out send slots ``1/rate`` apart from one schedule shared by all
connections (one wrk thread: one Lua state), so requests leave on time while the server
keeps up; the table shows the rate achieved. A slot missed because every connection was
busy is skipped, not made up for, and wrk times a request from its send, so when the server
falls behind the achieved rate drops below the target: read that column before the p99.

    apt-get install wrk
    .venv/bin/python benchmarks/api_load.py --db sqlite --seconds 10
    .venv/bin/python benchmarks/api_load.py --db postgres \\
        --postgres-url postgresql+psycopg://postgres@127.0.0.1:5432/test
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import httpx
from harness import ROOT, LeagueServer, ResultTable, add_record_option, start_league, write

from arena.config import RaceConfig
from arena.race import CarResult, RaceResult
from league import crud
from league.db import make_engine, make_session_factory, scratch_schema
from league.demo import demo_events
from league.migrations import upgrade
from league.models import Entry, Model
from league.store.local import LocalFileStore

PACER = """
local ffi = require("ffi")
ffi.cdef[[ typedef struct { long tv_sec; long tv_nsec; } bench_ts;
           int clock_gettime(int, bench_ts *); ]]
local ts = ffi.new("bench_ts")
local interval, slot = 1000 / %(rate)f, nil
function delay()  -- ms until this connection's next request: the next free send slot
  ffi.C.clock_gettime(1, ts)
  local now = tonumber(ts.tv_sec) * 1000 + tonumber(ts.tv_nsec) / 1e6
  slot = slot and math.max(slot + interval, now) or now
  return slot - now
end
"""


def seed(url: str, data_dir: Path, racers: int, races_each: int) -> tuple[int, int]:
    """The demo's events; the first one raced by ``racers`` racers; its id and a race id."""
    engine = make_engine(url)
    upgrade(engine)
    storage = LocalFileStore(data_dir / "files")
    steps = 450
    with make_session_factory(engine)() as session:
        admin, _ = crud.create_racer(session, "admin", admin=True)
        events = [crud.create_event(session, spec, admin.id) for spec in demo_events(60)]
        event = events[0]
        config = RaceConfig.build(**event.ruleset, cars=[{"name": "car0"}])
        race_id = 0
        for i in range(racers):
            racer, _ = crud.create_racer(session, f"racer{i:04d}")
            model = Model(owner_id=racer.id, name=f"m{i}", sha256=f"{i:064x}", size=1, info={})
            session.add(model)
            session.flush()
            entry = Entry(event_id=event.id, model_id=model.id, racer_id=racer.id)
            session.add(entry)
            session.commit()
            for r in range(races_each):
                laps = [9.0 + (i * 7 + r * 3) % 17 / 10.0 for _ in range(3)]
                car = CarResult(
                    "car0", "finished", 3, laps, min(laps), sum(laps) / 3, sum(laps),
                    i % 3, 0, 0, 0.0, 60.0, 1,
                )  # fmt: skip
                columns = {k: [round(0.01 * s * (j + 1), 3) for s in range(steps)]
                           for j, k in enumerate(("t", "x", "y", "heading", "speed"))}  # fmt: skip
                result = RaceResult(config, [car], ["car0"], 30.0, steps, {"car0": columns})
                race_id = crud.record_race(session, storage, event, result, {"car0": entry}).id
        event_id = event.id
    engine.dispose()
    return event_id, race_id


def cores() -> tuple[int, int]:
    """The server's core and wrk's (the same one on a one-core machine)."""
    available = sorted(os.sched_getaffinity(0))
    return available[0], available[1 % len(available)]


def start_server(url: str, data_dir: Path, port: int, core: int, tree: Path = ROOT) -> LeagueServer:
    """``slipstream league serve`` of ``tree`` on ``core`` (rate limit off), ready.
    Another ``tree`` (an older checkout) measures that code against the same data."""
    env = {
        **os.environ,
        "SLIPSTREAM_DATABASE_URL": url,
        "SLIPSTREAM_RATE_LIMIT_PER_SECOND": "0",
        "PYTHONPATH": str(tree),
    }
    args = ["--data-dir", str(data_dir)]
    if tree == ROOT:
        args.append("--no-access-log")  # older trees log every request (as they did)
    return start_league(*args, port=port, env=env, cwd=tree, core=core)


@dataclass
class Run:
    """What one wrk run measured."""

    rate: float
    p50_ms: float
    p99_ms: float
    errors: int

    def cells(self) -> list[str]:
        """Rate, p50 and p99 as table cells."""
        return [f"{self.rate:.0f}", f"{self.p50_ms:.1f}", f"{self.p99_ms:.1f}"]


UNITS = {"us": 1e-3, "ms": 1.0, "s": 1000.0}


def _ms(text: str) -> float:
    value, unit = re.fullmatch(r"([\d.]+)(us|ms|s)", text).groups()  # type: ignore[union-attr]
    return float(value) * UNITS[unit]


def wrk(url: str, connections: int, seconds: float, core: int, **options: object) -> Run:
    """One wrk run on ``core``; ``script`` (a Lua file) and ``headers`` optional."""
    command = [
        "taskset",
        "-c",
        str(core),
        "wrk",
        "-t1",
        f"-c{connections}",
        f"-d{max(1, round(seconds))}s",
    ]
    command += ["--latency", "--timeout", "10s"]
    for header in options.get("headers", ()):  # type: ignore[attr-defined]
        command += ["-H", header]
    if options.get("script"):
        command += ["-s", str(options["script"])]
    out = subprocess.run([*command, url], capture_output=True, text=True, check=True).stdout
    latency = dict(re.findall(r"^\s+(50|99)%\s+(\S+)\s*$", out, re.MULTILINE))
    if "50" not in latency or "99" not in latency:
        raise RuntimeError(f"wrk printed no latency distribution:\n{out}")
    errors = sum(int(n) for n in re.findall(r"Non-2xx or 3xx responses: (\d+)", out))
    errors += sum(int(n) for n in re.findall(r"(?:connect|read|write|timeout) (\d+)", out))
    rate = float(re.search(r"Requests/sec:\s+([\d.]+)", out).group(1))  # type: ignore[union-attr]
    return Run(rate, _ms(latency["50"]), _ms(latency["99"]), errors)


def measure(url: str, args: argparse.Namespace, label: str) -> list[list[str]]:
    """Prepare, serve and measure one database; the table rows."""
    server_core, wrk_core = cores()
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        data_dir = Path(folder)
        event, race = seed(url, data_dir, args.racers, args.races)
        tree = args.server_path.resolve()
        with start_server(url, data_dir, args.port, server_core, tree) as server:
            base = server.url
            etag = httpx.get(f"{base}/api/events/{event}/leaderboard").headers.get("etag", "")
            pacer = data_dir / "pacer.lua"
            pacer.write_text(PACER % {"rate": args.rate})
            routes = {
                "home page /": ("/", []),
                "event page": (f"/events/{event}", []),
                "leaderboard": (f"/api/events/{event}/leaderboard", []),
                "leaderboard 304": (f"/api/events/{event}/leaderboard", [f"If-None-Match: {etag}"]),
                "races list": (f"/api/races?event={event}&limit=20", []),
                "race detail": (f"/api/races/{race}", []),
                "trace": (f"/api/races/{race}/trace", []),
                "trace (gzip)": (f"/api/races/{race}/trace", ["Accept-Encoding: gzip"]),
                "track": ("/api/tracks/slipstream_speedway", []),
            }
            for name, (path, headers) in routes.items():
                wrk(base + path, 4, 1, wrk_core, headers=headers)  # warm up
                runs = [wrk(base + path, c, args.seconds, wrk_core, headers=headers)
                        for c in (16, 64)]  # fmt: skip
                paced = wrk(base + path, 32, args.seconds, wrk_core, headers=headers, script=pacer)
                cells = [cell for r in (*runs, paced) for cell in r.cells()]
                errors = sum(r.errors for r in (*runs, paced))
                rows.append([label, name, *cells, str(errors)])
                print(" | ".join(rows[-1]), flush=True)
    return rows


def main() -> None:
    """Parse options, check for wrk, measure, write the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", choices=["sqlite", "postgres"], default="sqlite")
    parser.add_argument(
        "--postgres-url",
        default=os.environ.get("SLIPSTREAM_TEST_POSTGRES_URL"),
        help="PostgreSQL URL (default: $SLIPSTREAM_TEST_POSTGRES_URL)",
    )
    parser.add_argument("--seconds", type=int, default=5, help="per wrk run")
    parser.add_argument("--rate", type=float, default=500.0, help="fixed-rate run, req/s")
    parser.add_argument("--racers", type=int, default=50)
    parser.add_argument("--races", type=int, default=3, help="races per racer")
    parser.add_argument("--port", type=int, default=8765)
    parser.add_argument(
        "--server-path",
        type=Path,
        default=ROOT,
        help="serve another checkout (e.g. a git worktree of an older commit) on the same data",
    )
    add_record_option(parser)
    args = parser.parse_args()
    if shutil.which("wrk") is None or shutil.which("taskset") is None:
        sys.exit("benchmarks/api_load.py needs wrk and taskset: apt-get install wrk util-linux")
    server_core, wrk_core = cores()
    cores_note = f"server on core {server_core}, wrk on core {wrk_core}"
    print(cores_note, flush=True)
    paced = f"@{args.rate:.0f}/s"
    columns = ["db", "route", "c16 req/s", "c16 p50 ms", "c16 p99 ms", "c64 req/s", "c64 p50 ms",
               "c64 p99 ms", f"{paced} got", f"{paced} p50 ms", f"{paced} p99 ms",
               "errors"]  # fmt: skip
    print(" | ".join(columns), flush=True)
    if args.db == "sqlite":
        with tempfile.TemporaryDirectory() as folder:
            rows = measure(f"sqlite:///{folder}/league.db", args, "sqlite")
    else:
        if not args.postgres_url:
            sys.exit("--db postgres: give --postgres-url or set SLIPSTREAM_TEST_POSTGRES_URL")
        url, drop = scratch_schema(args.postgres_url, "league_bench")
        try:
            rows = measure(url, args, "postgres")
        finally:
            drop()
    table = ResultTable(
        f"League reads under wrk load, {args.seconds} s per run", columns, "ll" + "r" * 10
    )
    for row in rows:
        table.add_row(*row)
    table.notes.append(cores_note)
    write(table, args.record)


if __name__ == "__main__":
    main()
