"""``slipstream demo`` end to end: real server, scheduler and worker processes."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import pytest

from league.demo import RACERS

pytestmark = pytest.mark.slow


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def test_demo_runs_entries_to_leaderboards(tmp_path: Path) -> None:
    port = _free_port()
    args = ["demo", "--out", str(tmp_path), "--port", str(port), "--no-serve", "--timeout", "240"]
    demo = subprocess.Popen(
        [sys.executable, "-m", "slipstream", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
    )
    try:
        out, err = demo.communicate(timeout=420)
    except subprocess.TimeoutExpired:
        demo.terminate()  # the demo stops its server, worker and scheduler as on Ctrl-C
        out, err = demo.communicate(timeout=60)
        pytest.fail(f"the demo ran past 420 s:\n{out[-3000:]}{err[-3000:]}")
    assert demo.returncode == 0, out[-3000:] + err[-3000:]
    assert "beginner_loop" in out and (tmp_path / "beginner_loop.png").exists()
    for title in ("Time Trial", "Object Avoidance", "Head-to-Bot", "Head-to-Model"):
        assert title in out
    for alias in RACERS:  # a row per event for each bundled sample model
        assert out.count(alias) >= 4, alias
    assert "not every first race finished" not in out
    assert "stopped the league's processes" in out
    with socket.socket() as sock:  # the server is gone
        assert sock.connect_ex(("127.0.0.1", port)) != 0
