"""League test fixtures: a real uvicorn server per test module, on SQLite and PostgreSQL.

Each module gets a fresh data directory. The PostgreSQL variant runs when
``SLIPSTREAM_TEST_POSTGRES_URL`` is set and uses its own schema, dropped afterwards; without
it the variant skips, or fails under ``CI=true`` (see ``tests.prerequisites``).
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import httpx
import numpy as np
import pytest
import uvicorn
from fastapi import FastAPI
from onnx import TensorProto, helper, numpy_helper
from sqlalchemy.orm import Session, sessionmaker

from arena.actions import default_discrete_space
from league import crud
from league.db import make_engine, make_session_factory, scratch_schema
from league.http.app import create_app
from league.http.server_options import server_config
from league.migrations import upgrade
from league.settings import Settings
from league.store.local import LocalFileStore
from submissions import pack
from tests.prerequisites import postgres_url

UPLOAD_LIMIT = 256 * 1024
CREATED_AT = datetime(2026, 11, 22, 12, 0, tzinfo=UTC)


def policy_onnx(seed: int = 0, n_in: int = 64, n_out: int = 10) -> bytes:
    """A tiny lidar MLP policy (batch, 64) -> (batch, 10) logits; ``seed`` changes weights."""
    rng = np.random.default_rng(seed)
    inits = [
        numpy_helper.from_array(rng.normal(size=(n_in, 8)).astype(np.float32), "w1"),
        numpy_helper.from_array(np.zeros(8, np.float32), "b1"),
        numpy_helper.from_array(rng.normal(size=(8, n_out)).astype(np.float32), "w2"),
        numpy_helper.from_array(np.zeros(n_out, np.float32), "b2"),
    ]
    nodes = [
        helper.make_node("Gemm", ["lidar", "w1", "b1"], ["h"]),
        helper.make_node("Relu", ["h"], ["r"]),
        helper.make_node("Gemm", ["r", "w2", "b2"], ["out"]),
    ]
    graph = helper.make_graph(
        nodes,
        "policy",
        [helper.make_tensor_value_info("lidar", TensorProto.FLOAT, ["batch", n_in])],
        [helper.make_tensor_value_info("out", TensorProto.FLOAT, ["batch", n_out])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    return model.SerializeToString()


def make_model_zip(folder: Path, seed: int = 0) -> Path:
    """A valid submission archive (lidar, default discrete actions); one per seed."""
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / f"model-{seed}.zip"
    return pack(out, policy_onnx(seed), default_discrete_space(), ["lidar"], created_at=CREATED_AT)


def free_port() -> int:
    """A currently free localhost TCP port."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class ServerThread:
    """uvicorn serving a league app in a background thread, configured as ``league serve``
    configures it (:func:`league.http.server_options.server_config`)."""

    def __init__(self, app: FastAPI, port: int) -> None:
        settings = app.state.settings
        config = server_config(app, settings, host="127.0.0.1", port=port, log_level="warning")
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.url = f"http://127.0.0.1:{port}"

    def __enter__(self) -> ServerThread:
        self.thread.start()
        deadline = time.monotonic() + 20
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError("uvicorn did not start")
            time.sleep(0.02)
        return self

    def __exit__(self, *_exc: object) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)


@dataclass
class Database:
    """A fresh database for one module: its URL and how to drop it afterwards."""

    url: str
    backend: str
    drop: object = field(default=lambda: None)


def _postgres_database() -> Database:
    url, drop = scratch_schema(postgres_url(), "league_test")
    return Database(url, "postgres", drop)


@pytest.fixture(scope="module", params=["sqlite", "postgres"])
def database(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):
    """An empty database: SQLite in a fresh folder, or a fresh PostgreSQL schema."""
    if request.param == "postgres":
        db = _postgres_database()
    else:
        folder = tmp_path_factory.mktemp("sqlite")
        db = Database(f"sqlite:///{folder / 'league.db'}", "sqlite")
    yield db
    db.drop()


@dataclass
class League:
    """A running league server and direct access to its database and files."""

    url: str
    settings: Settings
    sessions: sessionmaker[Session]
    storage: LocalFileStore
    backend: str
    tokens: dict[str, str]
    ids: dict[str, int]
    models_dir: Path

    def client(self, who: str | None = None) -> httpx.Client:
        """An HTTP client acting as ``who`` (admin, alice, bob) or anonymous."""
        headers = {"Authorization": f"Bearer {self.tokens[who]}"} if who else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=30)


def start_league(database: Database, data_dir: Path, **overrides: object) -> Iterator[League]:
    """Migrate, create admin / alice / bob, serve; yield the league; stop the server."""
    given = {"max_upload_bytes": UPLOAD_LIMIT, "rate_limit_per_second": 0, **overrides}
    settings = Settings(data_dir=data_dir, database_url=database.url, **given)
    engine = make_engine(settings.db_url)
    upgrade(engine)
    sessions = make_session_factory(engine)
    tokens, ids = {}, {}
    with sessions() as session:
        for alias in ("admin", "alice", "bob"):
            racer, token = crud.create_racer(session, alias, admin=alias == "admin")
            tokens[alias], ids[alias] = token, racer.id
    app = create_app(settings)
    with ServerThread(app, free_port()) as server:
        yield League(
            url=server.url,
            settings=settings,
            sessions=sessions,
            storage=LocalFileStore(settings.storage_dir),
            backend=database.backend,
            tokens=tokens,
            ids=ids,
            models_dir=data_dir.parent / "uploads",
        )
    app.state.engine.dispose()
    engine.dispose()


@pytest.fixture(scope="module")
def league(database: Database, tmp_path_factory: pytest.TempPathFactory) -> Iterator[League]:
    """A running server on a fresh database and data directory (one per test module)."""
    yield from start_league(database, tmp_path_factory.mktemp("league") / "data")
