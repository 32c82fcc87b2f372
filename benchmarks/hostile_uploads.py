"""Hostile uploads against a real league server: its memory, `/healthz` latency, verdicts.

Starts `python -m league serve` (SQLite, rate limits off) in a subprocess on loopback, with
``--server-path`` first on its ``PYTHONPATH`` (point it at an old checkout to measure
"before"), and sends the files from this process. While each scenario runs it samples the
RSS of the server process and of its children from ``/proc`` every 20 ms, and times
``GET /healthz`` every 100 ms. Prints one table.

Scenarios (files built in milliseconds by this folder's ``hostile_models``):
broadcast bomb (n, 1) + (1, n), one and two at once; ``--chain`` constant 2048 x 2048
MatMuls; ``--flood`` different valid wide MLPs at once (each steps in about 0.6 ms); the
same file twice at once, five times.

    .venv/bin/python benchmarks/hostile_uploads.py
    .venv/bin/python benchmarks/hostile_uploads.py --server-path /tmp/pre15
"""

from __future__ import annotations

import argparse
import collections
import os
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import httpx
from harness import ROOT, LeagueServer, ResultTable, add_record_option, rss_kib, start_league, write
from hostile_models import broadcast_bomb, matmul_chain, wide_mlp


def _descendants(pid: int) -> list[int]:
    found, todo = [], [pid]
    while todo:
        parent = todo.pop()
        for task in Path(f"/proc/{parent}/task").glob("*/children"):
            try:
                kids = [int(k) for k in task.read_text().split()]
            except OSError:
                continue
            found += kids
            todo += kids
    return found


@dataclass
class Probe:
    """Samples a server's memory and `/healthz` latency on background threads."""

    pid: int
    url: str
    server_peak_kib: int = 0
    children_peak_kib: int = 0
    health_worst_s: float = 0.0
    health_failures: int = 0
    stop: threading.Event = field(default_factory=threading.Event)

    def _memory(self) -> None:
        while not self.stop.wait(0.02):
            self.server_peak_kib = max(self.server_peak_kib, rss_kib(self.pid))
            kids = sum(rss_kib(k) for k in _descendants(self.pid))
            self.children_peak_kib = max(self.children_peak_kib, kids)

    def _health(self) -> None:
        with httpx.Client(base_url=self.url, timeout=60) as client:
            while not self.stop.wait(0.1):
                start = time.perf_counter()
                try:
                    ok = client.get("/healthz").status_code == 200
                except httpx.HTTPError:
                    ok = False
                self.health_worst_s = max(self.health_worst_s, time.perf_counter() - start)
                self.health_failures += not ok

    def __enter__(self) -> Probe:
        self.threads = [threading.Thread(target=t) for t in (self._memory, self._health)]
        for thread in self.threads:
            thread.start()
        return self

    def __exit__(self, *_exc: object) -> None:
        self.stop.set()
        for thread in self.threads:
            thread.join()


def _upload(url: str, token: str, data: bytes, name: str) -> tuple[int, float, str]:
    start = time.perf_counter()
    headers = {"Authorization": f"Bearer {token}"}
    try:
        with httpx.Client(base_url=url, headers=headers, timeout=300) as client:
            response = client.post("/api/models", files={"file": (f"{name}.zip", data)})
        status, body = response.status_code, response.text
    except httpx.HTTPError as exc:
        status, body = 0, f"{type(exc).__name__}: {exc}"
    return status, time.perf_counter() - start, body


def _scenario(server: LeagueServer, token: str, name: str, files: list[bytes]) -> dict[str, object]:
    with Probe(server.process.pid, server.url) as probe, ThreadPoolExecutor(len(files)) as pool:
        send = lambda i: _upload(server.url, token, files[i], f"f{i}")  # noqa: E731
        answers = list(pool.map(send, range(len(files))))
    time.sleep(0.5)
    slow = sum("too slow" in body for _, _, body in answers)
    return {
        "scenario": name,
        "answers": collections.Counter(status for status, _, _ in answers),
        "too slow": slow,
        "slowest answer s": max(seconds for _, seconds, _ in answers),
        "API peak MB": probe.server_peak_kib / 1024,
        "children peak MB": probe.children_peak_kib / 1024,
        "API after MB": rss_kib(server.process.pid) / 1024,
        "healthz worst ms": probe.health_worst_s * 1000,
        "healthz failed": probe.health_failures,
    }


def _start(
    server_path: Path, data_dir: Path, port: int, memory_cap_mb: int
) -> tuple[LeagueServer, str]:
    """A racer made, then the server of ``server_path`` started: the server and the token."""
    env = {
        **os.environ,
        "PYTHONPATH": str(server_path),
        "SLIPSTREAM_DATA_DIR": str(data_dir),
        "SLIPSTREAM_RATE_LIMIT_PER_SECOND": "0",
    }
    python = [sys.executable, "-m", "league"]
    made = subprocess.run(
        [*python, "create-racer", "hostile"], env=env, cwd=server_path, check=True,
        capture_output=True, text=True,
    )  # fmt: skip
    token = made.stdout.strip().splitlines()[-1]
    cap = ["prlimit", f"--as={memory_cap_mb * 1024 * 1024}"] if memory_cap_mb else []
    server = start_league("--host", "127.0.0.1", port=port, env=env, cwd=server_path, prefix=cap)
    return server, token


def _cell(value: object) -> str:
    """A table cell: answer counts as ``NxCODE``, floats to one decimal."""
    if isinstance(value, collections.Counter):
        return " ".join(f"{n}x{code}" for code, n in sorted(value.items()))
    return f"{value:.1f}" if isinstance(value, float) else str(value)


def main() -> None:
    """Run the scenarios against one server and write the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--server-path", type=Path, default=ROOT)
    parser.add_argument("--port", type=int, default=8765)
    parser.add_argument("--bomb", type=int, default=16384, help="n of the (n,1)+(1,n) bomb")
    parser.add_argument("--chain", type=int, default=30, help="chained 2048^2 MatMuls")
    parser.add_argument("--flood", type=int, default=40, help="valid uploads at once")
    parser.add_argument("--memory-cap-mb", type=int, default=0, help="prlimit --as on the server")
    add_record_option(parser)
    args = parser.parse_args()
    valid = [wide_mlp(2048, seed=i) for i in range(args.flood)]
    pairs = [wide_mlp(256, seed=10_000 + i) for i in range(5)]
    scenarios = [
        ("broadcast bomb, 1", [broadcast_bomb(args.bomb)]),
        ("broadcast bomb, 2 at once", [broadcast_bomb(args.bomb + i) for i in (1, 2)]),
        (f"{args.chain} chained MatMuls", [matmul_chain(args.chain)]),
        (f"{args.flood} valid at once", valid),
    ]
    with tempfile.TemporaryDirectory() as tmp:
        path, data_dir = args.server_path.resolve(), Path(tmp) / "data"
        server, token = _start(path, data_dir, args.port, args.memory_cap_mb)
        with server:
            rows = [_scenario(server, token, name, files) for name, files in scenarios]
            twins = [
                _scenario(server, token, "same file twice at once, 5 pairs", [f, f]) for f in pairs
            ]
            answers = sum((row["answers"] for row in twins), collections.Counter())
            rows.append({**twins[-1], "answers": answers})
    table = ResultTable("Hostile uploads against one league server", list(rows[0]))
    for row in rows:
        table.add_row(*(_cell(value) for value in row.values()))
    table.notes.append(f"server code: {args.server_path.resolve()}")
    write(table, args.record)


if __name__ == "__main__":
    main()
