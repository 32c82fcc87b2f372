"""Fixtures for the scheduler / worker reliability tests: a fresh database per test.

SQLite always; PostgreSQL too when ``SLIPSTREAM_TEST_POSTGRES_URL`` is set (a fresh schema
per test, dropped afterwards; without it that variant skips, or fails under ``CI=true``).
Worker and scheduler processes are real ``python -m`` processes pointed at the same
database through ``SLIPSTREAM_*`` variables.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from sqlalchemy import Engine
from sqlalchemy.orm import Session, sessionmaker

from league.db import make_engine, make_session_factory, scratch_schema
from league.migrations import upgrade
from league.settings import Settings
from league.store.local import LocalFileStore
from tests.prerequisites import postgres_url

ROOT = Path(__file__).resolve().parents[2]
FAST = {"lease_seconds": 2.0, "poll_seconds": 0.2, "sqlite_busy_timeout_ms": 2000}


@dataclass
class Ops:
    """One test's database, data directory and the processes started against them."""

    url: str
    backend: str
    data_dir: Path
    engine: Engine
    sessions: sessionmaker[Session]
    storage: LocalFileStore
    settings: Settings
    procs: list[subprocess.Popen] = field(default_factory=list)

    def env(self, **extra: object) -> dict[str, str]:
        """Environment for a child process using this database (fast leases)."""
        env = {**os.environ, "SLIPSTREAM_DATA_DIR": str(self.data_dir)}
        env["SLIPSTREAM_DATABASE_URL"] = self.url
        for key, value in {**FAST, **extra}.items():
            env[f"SLIPSTREAM_{key.upper()}"] = str(value)
        return env

    def start(self, module: str, name: str, **extra: object) -> subprocess.Popen:
        """Start ``python -m league.jobs.<module>`` (``worker`` or ``scheduler``); output
        goes to ``<data>/<name>.log``."""
        log = (self.data_dir / f"{name}.log").open("ab")
        args = [sys.executable, "-m", f"league.jobs.{module}"]
        args += ["--name", name] if module == "worker" else []
        proc = subprocess.Popen(
            args, cwd=ROOT, env=self.env(**extra), stdout=log, stderr=subprocess.STDOUT
        )
        self.procs.append(proc)
        return proc

    def log(self, name: str) -> str:
        """What a started process wrote so far."""
        path = self.data_dir / f"{name}.log"
        return path.read_text() if path.exists() else ""


@pytest.fixture(params=["sqlite", "postgres"])
def ops(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Ops]:
    """A migrated, empty database and data directory; started processes are killed after."""
    drop = None
    if request.param == "postgres":
        url, drop = scratch_schema(postgres_url(), "league_ops")
    else:
        url = f"sqlite:///{tmp_path / 'league.db'}"
    data_dir = tmp_path / "data"
    data_dir.mkdir()
    settings = Settings(data_dir=data_dir, database_url=url, **FAST)
    engine = make_engine(url, settings.sqlite_busy_timeout_ms)
    upgrade(engine)
    ops = Ops(
        url,
        request.param,
        data_dir,
        engine,
        make_session_factory(engine),
        LocalFileStore(settings.storage_dir),
        settings,
    )
    yield ops
    for proc in ops.procs:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    engine.dispose()
    if drop is not None:
        drop()
