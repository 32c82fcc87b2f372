"""Anonymous oversized JSON bodies against a real server: its memory and ``/healthz`` meanwhile.

Starts ``python -m league serve`` on loopback in a fresh data directory, then a separate
load process that posts ``--clients`` anonymous JSON bodies of ``--mb`` MB at once to
``POST /api/events/1/entries``. Meanwhile this process samples the server's RSS
(``/proc/PID/status``) and times ``GET /healthz`` every 50 ms. Then it trickles a small body
in, a byte every 0.1 s, and times the 408 that cuts it off (the server's body deadline set
to ``DEADLINE_S``). Prints one table.

    .venv/bin/python benchmarks/body_flood.py [--clients 8] [--mb 50]

Run it from another tree (``PYTHONPATH=/other/tree``) to measure that tree's server.
"""

from __future__ import annotations

import argparse
import json
import os
import select
import socket
import subprocess
import sys
import tempfile
import threading
import time

from harness import (
    ResultTable,
    add_record_option,
    healthz_seconds,
    rss_kib,
    start_league,
    write,
)

PATH = "/api/events/1/entries"
CHUNK = 1024 * 1024
DEADLINE_S = 1.0  # the server's deadline for a (non-upload) body to arrive
TRICKLE_S = 0.1


def post(port: int, body: bytes, chunk: int = CHUNK, pause_s: float = 0.0) -> tuple[int, float]:
    """Send ``body`` like a browser would, ``chunk`` bytes every ``pause_s``: stop sending
    once the server answers. The status, and the seconds from connecting to the answer."""
    start = time.monotonic()
    head = (
        f"POST {PATH} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
        f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n"
    )
    with socket.create_connection(("127.0.0.1", port), timeout=120) as sock:
        sock.sendall(head.encode())
        try:
            for offset in range(0, len(body), chunk):
                if select.select([sock], [], [], pause_s)[0]:
                    break  # answered early: the rest is not wanted
                sock.sendall(body[offset : offset + chunk])
        except OSError:
            pass  # the server closed after answering
        answer = sock.recv(64)
    status = int(answer.split(b" ", 2)[1]) if answer else 0
    return status, time.monotonic() - start


def load(port: int, clients: int, megabytes: int) -> None:
    """The load process: ``clients`` posts at once; prints their statuses and seconds."""
    body = b'{"model_id": 1, "pad": "' + b"x" * (megabytes * 1_000_000 - 26) + b'"}'
    results: list[tuple[int, float]] = []
    threads = [
        threading.Thread(target=lambda: results.append(post(port, body))) for _ in range(clients)
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    print(json.dumps(results))


def measure(clients: int, megabytes: int, record: bool) -> None:
    """Flood a fresh server, then trickle a body into it; write the table."""
    env = {**os.environ, "SLIPSTREAM_BODY_TIMEOUT_SECONDS": str(DEADLINE_S)}
    with (
        tempfile.TemporaryDirectory(prefix="body-flood-") as data_dir,
        start_league("--data-dir", data_dir, env=env) as server,
    ):
        port, pid = server.port, server.process.pid
        time.sleep(0.5)
        idle = rss_kib(pid) / 1024
        command = [sys.executable, __file__, "--load", str(port)]
        command += ["--clients", str(clients), "--mb", str(megabytes)]
        started = time.monotonic()
        loader = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
        peak, worst = idle, 0.0
        while loader.poll() is None:
            peak = max(peak, rss_kib(pid) / 1024)
            worst = max(worst, healthz_seconds(port))
            time.sleep(0.05)
        elapsed = time.monotonic() - started
        results = json.loads(loader.stdout.read())
        trickled, cut_off = post(port, b" " * 300, chunk=1, pause_s=TRICKLE_S)
    statuses = sorted({status for status, _ in results})
    slowest = max(seconds for _, seconds in results)
    title = f"{clients} anonymous {megabytes} MB JSON posts at once to POST {PATH}"
    table = ResultTable(title, ("measure", "value"))
    rows = [
        ("answers", ",".join(map(str, statuses))),
        ("slowest answer (s)", f"{slowest:.2f}"),
        ("whole flood (s)", f"{elapsed:.2f}"),
        ("server RSS idle (MB)", f"{idle:.0f}"),
        ("server RSS peak (MB)", f"{peak:.0f}"),
        ("server RSS growth (MB)", f"{peak - idle:.0f}"),
        ("worst /healthz meanwhile (s)", f"{worst:.3f}"),
        (f"a body trickled at 1 byte / {TRICKLE_S:g} s: answer", str(trickled)),
        (f"... its answer after the {DEADLINE_S:g} s deadline (s)", f"{cut_off - DEADLINE_S:.3f}"),
    ]
    for name, value in rows:
        table.add_row(name, value)
    write(table, record)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, default=8)
    parser.add_argument("--mb", type=int, default=50)
    parser.add_argument("--load", type=int, help=argparse.SUPPRESS)  # the load process's port
    add_record_option(parser)
    args = parser.parse_args()
    if args.load:
        load(args.load, args.clients, args.mb)
    else:
        measure(args.clients, args.mb, args.record)


if __name__ == "__main__":
    main()
