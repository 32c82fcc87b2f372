"""What one connection may cost, on the real ``slipstream league serve`` process: request
heads bounded in bytes and fields before they are parsed, a head-read timeout, idle
connections closed (issue 34, rows 1 and 6).

Every attack is a raw socket built here; the hang guards are at least 10x the limits.
"""

from __future__ import annotations

import os
import select
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from league.settings import Settings
from tests.league.conftest import free_port

HEAD_TIMEOUT_S = 1.0
HEAD_LIMIT = Settings().max_header_bytes
MB = 1_000_000
BODY_LIMIT = 16 * HEAD_LIMIT


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[int, subprocess.Popen]]:
    """``python -m league serve`` on a fresh data directory; its port and process."""
    port = free_port()
    data_dir = tmp_path_factory.mktemp("bounds")
    env = {**os.environ, "SLIPSTREAM_HEADER_TIMEOUT_SECONDS": str(HEAD_TIMEOUT_S)}
    env["SLIPSTREAM_MAX_BODY_BYTES"] = str(BODY_LIMIT)
    command = [sys.executable, "-m", "league", "serve", "--port", str(port)]
    command += ["--data-dir", str(data_dir), "--no-access-log"]
    log = (data_dir / "server.log").open("wb")
    process = subprocess.Popen(command, env=env, stdout=log, stderr=subprocess.STDOUT)
    try:
        _wait_ready(port, process, data_dir / "server.log")
        yield port, process
    finally:
        process.terminate()
        process.wait(timeout=30)
        log.close()


def _wait_ready(port: int, process: subprocess.Popen, log: Path) -> None:
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        assert process.poll() is None, log.read_text()
        try:
            if httpx.get(f"http://127.0.0.1:{port}/readyz", timeout=2).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.1)
    pytest.fail(f"the server did not become ready: {log.read_text()}")


def _connect(port: int) -> socket.socket:
    return socket.create_connection(("127.0.0.1", port), timeout=30)


def _status(answer: bytes) -> int:
    """The status code of an HTTP answer's first bytes (0: the server sent nothing)."""
    return int(answer.split(b" ", 2)[1]) if answer else 0


def _healthz(port: int) -> int:
    return httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=30).status_code


def _read_all(sock: socket.socket) -> bytes:
    """Everything the server sends until it closes the connection."""
    chunks = []
    try:
        while chunk := sock.recv(65536):
            chunks.append(chunk)
    except ConnectionResetError:
        pass
    return b"".join(chunks)


def test_a_header_bomb_gets_431_after_a_bounded_read(server: tuple[int, subprocess.Popen]):
    port, _ = server
    total_mb = 16  # stock uvicorn reads and parses it all (quadratically), then answers 200
    sent = 0
    with _connect(port) as sock:
        sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: test\r\nX-Bomb: ")
        try:
            for _ in range(total_mb):
                if select.select([sock], [], [], 0)[0]:
                    break  # answered: stop sending
                sock.sendall(b"a" * MB)
                sent += MB
            else:
                sock.sendall(b"\r\n\r\n")
        except (BrokenPipeError, ConnectionResetError):
            pass  # closed after answering
        answer = _read_all(sock)
    assert _status(answer) == 431, answer[:200]
    assert b"Request header fields too large." in answer
    # the server stopped reading near the limit: socket buffers hold a few MB at most
    assert sent < total_mb * MB // 2
    assert _healthz(port) == 200


def test_too_many_header_fields_get_431(server: tuple[int, subprocess.Popen]):
    port, _ = server
    fields = b"".join(b"X-Field-%d: %d\r\n" % (i, i) for i in range(Settings().max_header_count))
    with _connect(port) as sock:
        sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: test\r\n" + fields + b"\r\n")
        answer = _read_all(sock)
    assert _status(answer) == 431 and b"Too many request header fields." in answer


def test_heads_within_the_limits_are_served_pipelined_and_kept_alive(
    server: tuple[int, subprocess.Popen],
):
    port, _ = server
    cookie = b"Cookie: " + b"c" * (HEAD_LIMIT - 200) + b"\r\n"
    request = b"GET /healthz HTTP/1.1\r\nHost: test\r\n" + cookie + b"\r\n"
    with _connect(port) as sock:
        sock.sendall(request * 3)  # three big heads back to back, each under the limit
        answers = _read_healthz(sock, 3)
        for _ in range(2):  # the same connection serves more, a byte at a time
            for byte in b"GET /healthz HTTP/1.1\r\nHost: test\r\n\r\n":
                sock.sendall(bytes([byte]))
            assert _status(_read_healthz(sock, 1)) == 200
    assert answers.count(b"HTTP/1.1 200 OK") == 3


def test_a_long_body_does_not_count_against_the_next_head(server: tuple[int, subprocess.Popen]):
    port, _ = server
    body = b"x" * (8 * HEAD_LIMIT)
    post = b"POST /healthz HTTP/1.1\r\nHost: test\r\nContent-Length: %d\r\n\r\n" % len(body)
    with _connect(port) as sock:
        for _ in range(3):  # a refused body (405), then a read, on one kept-alive connection
            tail = 2 * HEAD_LIMIT  # the body's end in a read of its own, as an upload's is
            sock.sendall(post + body[:-tail])
            time.sleep(0.05)
            sock.sendall(body[-tail:])
            time.sleep(0.05)
            sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: test\r\n\r\n")
            answers = _read_healthz(sock, 1)
            assert _status(answers) == 405 and b"HTTP/1.1 200 OK" in answers, answers[:300]


def _read_healthz(sock: socket.socket, count: int) -> bytes:
    """What the server sends until ``count`` ``/healthz`` bodies have come."""
    answers = b""
    while answers.count(b'{"status":"ok"}') < count:
        chunk = sock.recv(65536)
        assert chunk, answers
        answers += chunk
    return answers


def test_a_head_sent_a_line_at_a_time_is_cut_off_with_408(server: tuple[int, subprocess.Popen]):
    port, _ = server
    pause_s, lines = HEAD_TIMEOUT_S / 4, 0
    max_lines = int(10 * HEAD_TIMEOUT_S / pause_s)  # the hang guard: 10x the timeout
    with _connect(port) as sock:
        sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: test\r\n")
        try:
            while lines < max_lines and not select.select([sock], [], [], pause_s)[0]:
                sock.sendall(b"X-Slow-%d: 1\r\n" % lines)
                lines += 1
        except (BrokenPipeError, ConnectionResetError):
            pass
        answer = _read_all(sock)
    assert _status(answer) == 408, (lines, answer[:200])
    assert lines < max_lines


def test_an_idle_connection_is_closed(server: tuple[int, subprocess.Popen]):
    port, _ = server
    with _connect(port) as sock:
        sock.settimeout(10 * HEAD_TIMEOUT_S)  # stock uvicorn keeps it open forever
        assert sock.recv(64) == b""  # closed by the server, nothing said
    assert _healthz(port) == 200


def test_idle_connections_do_not_lock_out_new_clients(server: tuple[int, subprocess.Popen]):
    port, process = server
    idle = [_connect(port) for _ in range(50)]
    try:
        for sock in idle:  # each one closed by the server
            sock.settimeout(10 * HEAD_TIMEOUT_S)
            assert sock.recv(64) == b""
        assert _open_sockets(process.pid) < 25
    finally:
        for sock in idle:
            sock.close()
    assert _healthz(port) == 200


def _open_sockets(pid: int) -> int:
    """How many sockets process ``pid`` holds open (from /proc)."""
    fds = Path(f"/proc/{pid}/fd")
    return sum(1 for fd in fds.iterdir() if os.readlink(fd).startswith("socket:"))
