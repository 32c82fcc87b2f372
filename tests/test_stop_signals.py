"""Every long-running command stops its children and itself on SIGTERM and SIGHUP as on
Ctrl-C (issue 34, row 13): ``slipstream demo``, ``league serve`` (one process and
``--workers``), ``league worker``, ``league scheduler`` and ``slipstream train``.

Each command runs for real in a session of its own; the signal goes to its process alone,
as ``kill``, systemd and container runtimes send it (a closed terminal's SIGHUP goes to
the whole group: the training case sends it so).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.agents.test_train_workers import TINY, _children, _wait_gone, _workers


def _free_port() -> int:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _descendants(pid: int) -> set[int]:
    """Every live process below ``pid``."""
    found, todo = set(), [pid]
    while todo:
        children = set(_children(todo.pop()))
        found |= children
        todo.extend(children)
    return found


def _answers(port: int) -> bool:
    try:
        httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=5)
    except httpx.HTTPError:
        return False
    return True


def _start(command: list[str], log: Path, **kw: object) -> subprocess.Popen:
    with log.open("wb") as out:
        return subprocess.Popen(
            command, stdout=out, stderr=subprocess.STDOUT, start_new_session=True, **kw
        )


def _wait_for(condition: object, what: str, log: Path, seconds: float = 120.0) -> None:
    deadline = time.monotonic() + seconds
    while not condition():  # type: ignore[operator]
        if time.monotonic() > deadline:
            pytest.fail(f"{what} did not happen in {seconds:g} s; output:\n{log.read_text()}")
        time.sleep(0.1)


@pytest.fixture
def reaper() -> Iterator[list[subprocess.Popen]]:
    """Processes to SIGKILL (with their sessions) if a test leaves them running."""
    started: list[subprocess.Popen] = []
    yield started
    for process in started:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


def _stop_and_check(process: subprocess.Popen, sig: int, below: set[int], log: Path) -> int:
    """Send ``sig`` to ``process`` alone; its exit code once every process below it is gone."""
    process.send_signal(sig)
    try:
        code = process.wait(timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail(f"still running 60 s after {signal.Signals(sig).name}:\n{log.read_text()}")
    left = _wait_gone(below, seconds=30.0)
    assert not left, f"outlived {signal.Signals(sig).name}: {left}\n{log.read_text()}"
    return code


# The demo and training are the costliest to start (15-20 s each): each is stopped by one
# signal, the other commands by both, so both signals stop both kinds of process tree.
@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGHUP], ids=lambda s: signal.Signals(s).name)
def test_demo_stops_server_worker_and_scheduler(tmp_path: Path, reaper: list, sig: int) -> None:
    port, log = _free_port(), tmp_path / "demo.log"
    command = [sys.executable, "-m", "slipstream", "demo", "--out", str(tmp_path / "out")]
    command += ["--port", str(port), "--timeout", "2"]
    demo = _start(command, log, cwd=tmp_path)
    reaper.append(demo)
    _wait_for(lambda: "serving until Ctrl-C" in log.read_text(), "the demo serving", log, 300)
    below = _descendants(demo.pid)
    assert len(below) >= 3 and _answers(port)  # server, worker (and its child), scheduler
    _stop_and_check(demo, sig, below, log)
    assert not _answers(port)
    assert "stopped the league's processes" in log.read_text()


@pytest.mark.parametrize("workers", [1, 2])
def test_serve_stops_on_sighup_as_on_sigterm(tmp_path: Path, reaper: list, workers: int) -> None:
    port, log = _free_port(), tmp_path / "serve.log"
    command = [sys.executable, "-m", "league", "serve", "--port", str(port)]
    command += ["--data-dir", str(tmp_path / "data"), "--workers", str(workers)]
    server = _start(command, log)
    reaper.append(server)
    _wait_for(lambda: _answers(port), "the server answering", log)
    below = _descendants(server.pid)  # --workers: uvicorn's worker processes
    _stop_and_check(server, signal.SIGHUP, below, log)
    assert not _answers(port)
    assert "Finished server process" in log.read_text()  # uvicorn's graceful shutdown


def test_worker_stops_its_processes_on_sighup(tmp_path: Path, reaper: list) -> None:
    log = tmp_path / "worker.log"
    command = [sys.executable, "-m", "league", "worker", "--concurrency", "2"]
    command += ["--data-dir", str(tmp_path / "data")]
    worker = _start(command, log)
    reaper.append(worker)
    _wait_for(lambda: log.read_text().count("started") >= 2, "two workers starting", log)
    below = _descendants(worker.pid)
    assert len(below) >= 2
    assert _stop_and_check(worker, signal.SIGHUP, below, log) == 0


def test_scheduler_stops_on_sighup(tmp_path: Path, reaper: list) -> None:
    log = tmp_path / "scheduler.log"
    command = [sys.executable, "-m", "league", "scheduler", "--data-dir", str(tmp_path / "d")]
    scheduler = _start(command, log)
    reaper.append(scheduler)
    _wait_for(lambda: "scheduler started" in log.read_text(), "the scheduler starting", log)
    assert _stop_and_check(scheduler, signal.SIGHUP, set(), log) == 0


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM], ids=lambda s: signal.Signals(s).name)
def test_train_stops_like_ctrl_c(tmp_path: Path, reaper: list, sig: int) -> None:
    run, hp, log = tmp_path / "run", tmp_path / "hp.json", tmp_path / "train.log"
    hp.write_text(TINY.model_dump_json())
    command = [sys.executable, "-m", "slipstream", "train", "--out", str(run), "--minutes", "5"]
    command += ["--sensors", "lidar", "--action-space", "3x3@1.0", "--workers", "2"]
    command += ["--eval-every", "1000", "--hyperparameters", str(hp)]
    env = {**os.environ, "COLUMNS": "200"}
    trainer = _start(command, log, env=env)
    reaper.append(trainer)
    metrics = run / "metrics.csv"
    _wait_for(
        lambda: metrics.exists() and len(metrics.read_text().splitlines()) >= 2,
        "a first iteration",
        log,
    )
    workers = _workers(trainer.pid)
    assert len(workers) == 2
    if sig == signal.SIGHUP:  # a closed terminal signals the whole process group
        os.killpg(trainer.pid, sig)
        code = _stop_and_check(trainer, 0, workers, log)  # signal 0: only waits
    else:
        code = _stop_and_check(trainer, sig, workers, log)
    assert code == 0, log.read_text()
    assert "stopped (Ctrl-C)" in log.read_text()
    assert (run / "checkpoints" / "last.pt").exists() and (run / "model" / "model.zip").exists()
