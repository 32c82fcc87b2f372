"""Hostile connections against a real server: header bombs and identity-encoded trace reads.

Starts ``python -m league serve`` on loopback in a fresh data directory holding one event
and one race with a long replay trace (``--steps`` steps of 4 cars), then runs each attack
from a separate load process while this process samples the server's RSS
(``/proc/PID/status``) and times ``GET /healthz`` every 50 ms:

- ``bomb``: one connection sends ``GET /healthz`` with a single header of ``--bomb-mb`` MB,
  1 MB a write, until the server answers or closes;
- ``held``: 5 connections each send an unfinished header of ``--held-mb`` MB and hold it;
- ``identity``: ``--clients`` clients read the trace with ``Accept-Encoding: identity``,
  ``--reads`` times each; ``gzip``: the same with gzip, for comparison.

Prints one table: per attack, what the attacker got, the server's peak RSS growth and the
worst ``/healthz`` meanwhile.

    .venv/bin/python benchmarks/hostile_connections.py [--bomb-mb 100] [--clients 8]

Run it from another tree (``PYTHONPATH=/other/tree``) to measure that tree's server.
"""

from __future__ import annotations

import argparse
import json
import select
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from harness import (
    ResultTable,
    add_record_option,
    healthz_seconds,
    rss_kib,
    start_league,
    write,
)

MB = 1_000_000
HELD_CONNECTIONS = 5
HOLD_S = 3.0


# ------------------------------------------------------------------------------ league
def seed_league(data_dir: Path, steps: int) -> int:
    """One event and one race whose trace has ``steps`` steps of 4 cars; the trace's size."""
    import random

    from league import crud
    from league.db import make_engine, make_session_factory
    from league.migrations import upgrade
    from league.models import Race
    from league.schemas import EventCreate
    from league.settings import Settings
    from league.store import open_storage

    settings = Settings(data_dir=data_dir)
    engine = make_engine(settings.db_url)
    upgrade(engine)
    rng = random.Random(0)
    cars = {
        f"car{i}": {k: [round(rng.uniform(-5, 5), 4) for _ in range(steps)] for k in "xyzvsa"}
        for i in range(4)
    }
    trace = json.dumps({"trace": cars, "bots": [], "obstacles": [], "events": []}).encode()
    sha, _ = open_storage(settings).put("traces", trace)
    with make_session_factory(engine)() as session:
        event = crud.create_event(session, EventCreate(name="Trace Cup"), None)
        race = Race(event_id=event.id, ruleset_hash=event.ruleset_hash, seed=0, config={},
                    summary={}, trace_sha256=sha)  # fmt: skip
        session.add(race)
        session.commit()
    engine.dispose()
    return len(trace)


# -------------------------------------------------------------------------- the attacks
def bomb(port: int, megabytes: int) -> dict:
    """One header of ``megabytes`` MB, 1 MB a write, until the server answers or closes."""
    start, sent, answer = time.monotonic(), 0, b""
    chunk = b"a" * MB
    with socket.create_connection(("127.0.0.1", port), timeout=120) as sock:
        try:
            sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Bomb: ")
            for _ in range(megabytes):
                if select.select([sock], [], [], 0)[0]:
                    break
                sock.sendall(chunk)
                sent += len(chunk)
            else:
                sock.sendall(b"\r\n\r\n")
            answer = sock.recv(64)
        except OSError:
            pass
    return {"sent_mb": sent / MB, "answer": answer[:12].decode(errors="replace"),
            "seconds": time.monotonic() - start}  # fmt: skip


def held(port: int, megabytes: int) -> dict:
    """``HELD_CONNECTIONS`` unfinished headers of ``megabytes`` MB each, held ``HOLD_S``."""
    socks, sent, closed = [], 0, 0
    chunk = b"a" * MB
    for _ in range(HELD_CONNECTIONS):
        sock = socket.create_connection(("127.0.0.1", port), timeout=120)
        socks.append(sock)
        try:
            sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Held: ")
            for _ in range(megabytes):
                if select.select([sock], [], [], 0)[0]:
                    closed += 1
                    break
                sock.sendall(chunk)
                sent += len(chunk)
        except OSError:
            closed += 1
    time.sleep(HOLD_S)
    for sock in socks:
        sock.close()
    return {"sent_mb": sent / MB, "refused": closed}


def trace_reads(port: int, clients: int, reads: int, encoding: str) -> dict:
    """``clients`` threads each read the trace ``reads`` times with ``Accept-Encoding:
    encoding``."""
    import httpx

    statuses: list[int] = []
    start = time.monotonic()

    def client() -> None:
        headers = {"Accept-Encoding": encoding}
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=120) as http:
            for _ in range(reads):
                statuses.append(http.get("/api/races/1/trace", headers=headers).status_code)

    threads = [threading.Thread(target=client) for _ in range(clients)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    elapsed = time.monotonic() - start
    return {"statuses": sorted(set(statuses)), "reads_per_s": len(statuses) / elapsed}


def load(args: argparse.Namespace) -> None:
    """The load process: run one attack, print what it saw as JSON."""
    port = args.port
    if args.load == "bomb":
        result = bomb(port, args.bomb_mb)
    elif args.load == "held":
        result = held(port, args.held_mb)
    else:
        result = trace_reads(port, args.clients, args.reads, args.load)
    print(json.dumps(result))


# --------------------------------------------------------------------------- measuring
def attack(name: str, port: int, pid: int, args: argparse.Namespace) -> tuple[dict, float, float]:
    """Run attack ``name`` in its own process; what it saw, peak RSS growth (MB), worst
    ``/healthz`` (s) meanwhile."""
    command = [sys.executable, __file__, "--load", name, "--port", str(port)]
    command += ["--bomb-mb", str(args.bomb_mb), "--held-mb", str(args.held_mb)]
    command += ["--clients", str(args.clients), "--reads", str(args.reads)]
    idle = rss_kib(pid) / 1024
    loader = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
    peak, worst = idle, 0.0
    while loader.poll() is None:
        peak = max(peak, rss_kib(pid) / 1024)
        worst = max(worst, healthz_seconds(port))
        time.sleep(0.05)
    return json.loads(loader.stdout.read()), peak - idle, worst


def measure(args: argparse.Namespace) -> None:
    """Seed a league, serve it, run the three attacks; write the table."""
    table = ResultTable(
        "Hostile connections: header bombs and identity-encoded trace reads",
        ("attack", "attacker got", "server RSS growth (MB)", "worst /healthz (s)"),
        align="llrr",
    )
    with tempfile.TemporaryDirectory(prefix="hostile-conn-") as data_dir:
        size = seed_league(Path(data_dir), args.steps)
        with start_league("--data-dir", data_dir, "--no-access-log") as server:
            port, pid = server.port, server.process.pid
            time.sleep(0.5)
            idle = rss_kib(pid) / 1024
            got, growth, worst = attack("bomb", port, pid, args)
            answer = got["answer"] or "no answer"
            table.add_row(f"one {args.bomb_mb} MB header",
                          f"{answer!r} after {got['sent_mb']:.0f} MB sent, {got['seconds']:.1f} s",
                          f"{growth:.0f}", f"{worst:.3f}")  # fmt: skip
            got, growth, worst = attack("held", port, pid, args)
            table.add_row(f"{HELD_CONNECTIONS} unfinished {args.held_mb} MB headers held",
                          f"{got['sent_mb']:.0f} MB taken, {got['refused']} refused",
                          f"{growth:.0f}", f"{worst:.3f}")  # fmt: skip
            for encoding in ("identity", "gzip"):
                got, growth, worst = attack(encoding, port, pid, args)
                table.add_row(f"{args.clients} clients x {args.reads} trace reads, {encoding}",
                              f"{got['statuses']}, {got['reads_per_s']:.1f} reads/s",
                              f"{growth:.0f}", f"{worst:.3f}")  # fmt: skip
    table.notes.append(
        f"server RSS idle {idle:.0f} MB; trace {size / MB:.1f} MB ({args.steps} steps x 4 cars)"
    )
    write(table, args.record)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bomb-mb", type=int, default=100)
    parser.add_argument("--held-mb", type=int, default=40)
    parser.add_argument("--clients", type=int, default=8)
    parser.add_argument("--reads", type=int, default=10)
    parser.add_argument("--steps", type=int, default=9000, help="trace length (600 s at 15 Hz)")
    attacks = ("bomb", "held", "identity", "gzip")
    parser.add_argument("--load", choices=attacks, help=argparse.SUPPRESS)
    parser.add_argument("--port", type=int, help=argparse.SUPPRESS)
    add_record_option(parser)
    args = parser.parse_args()
    if args.load:
        load(args)
    else:
        measure(args)


if __name__ == "__main__":
    main()
