"""What every benchmark shares: a league server to measure, timing statistics, and the one
table writer, which prints a result and appends it to ``benchmarks/results/``.

The scripts import it as ``harness``: Python puts a script's own folder first on its path.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import IO, Any

import httpx
import numpy as np
from rich.console import Console
from rich.table import Table
from rich.text import Text

ROOT = Path(__file__).resolve().parents[1]
"""The checkout these scripts belong to."""
RESULTS = Path(__file__).resolve().parent / "results"
"""Where :func:`write` appends each script's tables."""


# ------------------------------------------------------------------------------ server
class ServerNotReady(RuntimeError):
    """The league server exited, or did not answer ``/readyz``, in time."""


@dataclass
class LeagueServer:
    """A ``python -m league serve`` subprocess that answered ``/readyz``; its output goes
    to a temporary file. A context manager: leaving it stops the server."""

    process: subprocess.Popen
    port: int
    log: IO[bytes]

    @property
    def url(self) -> str:
        """Where it answers: ``http://127.0.0.1:PORT``."""
        return f"http://127.0.0.1:{self.port}"

    def output(self, limit: int = 4000) -> str:
        """The last ``limit`` characters the server wrote (stdout and stderr)."""
        self.log.flush()
        self.log.seek(0)
        return self.log.read().decode(errors="replace")[-limit:]

    def stop(self) -> None:
        """SIGTERM, up to 30 s to exit, then SIGKILL."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.log.close()

    def __enter__(self) -> LeagueServer:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.stop()


def spin() -> None:
    """Keep one core busy until killed (a load generator's process)."""
    while True:
        pass


def rss_kib(pid: int) -> int:
    """Resident memory of process ``pid`` in KiB, from ``/proc`` (0 once it is gone)."""
    resident = _proc_field(f"/proc/{pid}/status", "VmRSS")  # "123456 kB"
    return int(resident.split()[0]) if resident else 0


def healthz_seconds(port: int) -> float:
    """How long ``GET /healthz`` takes on a fresh raw connection (no client library)."""
    start = time.monotonic()
    with socket.create_connection(("127.0.0.1", port), timeout=60) as sock:
        sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
        sock.recv(64)
    return time.monotonic() - start


def free_port() -> int:
    """A loopback port nothing listens on now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def start_league(
    *serve_args: str,
    port: int | None = None,
    env: Mapping[str, str] | None = None,
    cwd: Path | None = None,
    prefix: Sequence[str] = (),
    core: int | None = None,
    timeout_s: float = 60.0,
) -> LeagueServer:
    """Start ``python -m league serve --port PORT *serve_args`` and wait until its
    ``/readyz`` answers 200.

    ``port`` defaults to a free one; ``env`` is the server's whole environment (default:
    this process's); ``prefix`` goes before the command (e.g. ``prlimit --as=N``); ``core``
    pins the server to that CPU. Raises :class:`ServerNotReady`, with the server's output,
    if it exits or is not ready within ``timeout_s``.
    """
    port = free_port() if port is None else port
    command = [*prefix, sys.executable, "-m", "league", "serve", "--port", str(port), *serve_args]
    log = tempfile.TemporaryFile()  # noqa: SIM115  (the server's: LeagueServer.stop closes it)
    process = subprocess.Popen(
        command,
        env=None if env is None else dict(env),
        cwd=cwd,
        stdout=log,
        stderr=subprocess.STDOUT,
        preexec_fn=None if core is None else lambda: os.sched_setaffinity(0, {core}),
    )
    server = LeagueServer(process, port, log)
    deadline = time.monotonic() + timeout_s
    while (code := process.poll()) is None and time.monotonic() < deadline:
        try:
            if httpx.get(f"{server.url}/readyz", timeout=2.0).status_code == 200:
                return server
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    if code is not None:
        problem = f"exited with code {code} before {server.url}/readyz answered 200"
    else:
        problem = f"was not ready at {server.url}/readyz within {timeout_s:g} s"
    output = server.output()
    server.stop()
    raise ServerNotReady(f"the league server {problem}: {shlex.join(command)}\n{output}")


# ----------------------------------------------------------------------------- timings
@dataclass(frozen=True)
class Timings:
    """Statistics of some durations, in their unit."""

    n: int
    mean: float
    median: float
    p95: float
    p99: float
    max: float


def summary(durations: Sequence[float]) -> Timings:
    """n, mean, median, p95, p99 (numpy's linear percentiles) and max of ``durations``."""
    values = np.asarray(durations, dtype=float)
    if values.size == 0:
        raise ValueError("no durations to summarise")
    median, p95, p99 = (float(p) for p in np.percentile(values, [50, 95, 99]))
    return Timings(values.size, float(values.mean()), median, p95, p99, float(values.max()))


def time_calls(call: Callable[[], object], runs: int, warmup: int = 0) -> list[float]:
    """Seconds each of ``runs`` calls of ``call`` took, after ``warmup`` untimed calls."""
    for _ in range(warmup):
        call()
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return times


# ------------------------------------------------------------------------------ tables
@dataclass
class ResultTable:
    """One table of a benchmark: what :func:`write` prints and records. ``align`` has a
    letter per column, ``l`` or ``r`` (default: the first left, the rest right)."""

    title: str
    columns: Sequence[str]
    align: str = ""
    rows: list[list[str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.align = self.align or "l" + "r" * (len(self.columns) - 1)
        if len(self.align) != len(self.columns) or set(self.align) - {"l", "r"}:
            raise ValueError(f"align {self.align!r}: one l or r per column {self.columns}")

    def add_row(self, *cells: object) -> None:
        """Append a row (cells already formatted; others are written with ``str``)."""
        if len(cells) != len(self.columns):
            raise ValueError(f"{len(cells)} cells for {len(self.columns)} columns")
        self.rows.append([str(cell) for cell in cells])


def add_record_option(parser: argparse.ArgumentParser) -> None:
    """``--no-record``: print the table only (``args.record`` is False)."""
    parser.add_argument(
        "--no-record",
        dest="record",
        action="store_false",
        help="print the table only: append nothing to benchmarks/results/",
    )


def write(
    table: ResultTable, record: bool = True, name: str | None = None, results: Path = RESULTS
) -> None:
    """Print ``table`` with rich, then (``record``) append it, stamped with the date, the
    commit, the machine and the command, to ``results/NAME.md`` as markdown and to
    ``results/NAME.jsonl`` as one JSON line; ``name`` defaults to the running script's."""
    entry = stamp() | {
        "title": table.title,
        "columns": list(table.columns),
        "rows": table.rows,
        "notes": table.notes,
    }
    console = Console(width=200)
    shown = Table(title=Text(table.title))
    for column, align in zip(table.columns, table.align, strict=True):
        shown.add_column(Text(column), justify="left" if align == "l" else "right")
    for row in table.rows:
        shown.add_row(*(Text(cell) for cell in row))
    console.print(shown)
    for line in [*table.notes, machine_line(entry)]:
        console.print(Text(line))
    if not record:
        return
    name = name or Path(sys.argv[0]).stem
    results.mkdir(parents=True, exist_ok=True)
    log = results / f"{name}.md"
    heading = "" if log.exists() else f"# Results of `{name}.py` (appended by each run)\n\n"
    with log.open("a") as handle:
        handle.write(heading + markdown(table, entry))
    with log.with_suffix(".jsonl").open("a") as handle:
        handle.write(json.dumps(entry) + "\n")
    console.print(Text(f"appended to {os.path.relpath(log)} and its .jsonl"))


def stamp() -> dict[str, Any]:
    """When, where and how a result was measured."""
    return {
        "date": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "command": shlex.join(sys.orig_argv),
        "commit": _commit(),
        "machine": machine(),
        "load_1min": round(os.getloadavg()[0], 2),
    }


def machine() -> dict[str, Any]:
    """This machine, not named: CPU model, cores, memory, and the GPU when torch is loaded
    already and sees one (torch is never imported for this)."""
    torch = sys.modules.get("torch")
    gpu = None
    if torch is not None and torch.cuda.is_available():
        gpu = torch.cuda.get_device_name(0)
    return {
        "cpu": _proc_field("/proc/cpuinfo", "model name") or platform.processor() or None,
        "cores": os.cpu_count(),
        "memory_gib": _memory_gib(),
        "gpu": gpu,
    }


def machine_line(entry: Mapping[str, Any]) -> str:
    """The stamp's machine and load in one line."""
    m = entry["machine"]
    memory = f"{m['memory_gib']:.1f} GiB" if m["memory_gib"] is not None else "memory unknown"
    return (
        f"{m['cpu'] or 'CPU unknown'}, {m['cores']} cores, {memory}, {m['gpu'] or 'no GPU'}; "
        f"1-min load average {entry['load_1min']:.1f}"
    )


def markdown(table: ResultTable, entry: Mapping[str, Any]) -> str:
    """One recorded entry as markdown: heading, stamp, table, notes."""
    lines = [
        f"## {table.title}",
        "",
        f"- date: {entry['date']}, commit {entry['commit'] or 'unknown'}",
        f"- command: `{entry['command']}`",
        f"- machine: {machine_line(entry)}",
        "",
        "| " + " | ".join(table.columns) + " |",
        "|" + "".join("---|" if a == "l" else "---:|" for a in table.align),
    ]
    for row in table.rows:
        lines.append("| " + " | ".join(cell.replace("|", "\\|") for cell in row) + " |")
    lines += [line for note in table.notes for line in ("", note)]
    return "\n".join(lines) + "\n\n"


def _proc_field(path: str, key: str) -> str | None:
    """The first ``key: value`` of a ``/proc`` file (None off Linux)."""
    try:
        with open(path) as handle:
            for line in handle:
                name, _, value = line.partition(":")
                if name.strip() == key:
                    return value.strip()
    except OSError:
        pass
    return None


def _memory_gib() -> float | None:
    """Installed memory in GiB, from ``/proc/meminfo`` (None off Linux)."""
    total = _proc_field("/proc/meminfo", "MemTotal")  # "16318480 kB"
    return round(int(total.split()[0]) / 2**20, 1) if total else None


def _commit() -> str | None:
    """The checkout's commit, ``-dirty`` when it has changes (None without git)."""
    try:
        done = subprocess.run(
            ["git", "-C", str(ROOT), "describe", "--always", "--dirty", "--abbrev=12"],
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    return done.stdout.strip() or None
