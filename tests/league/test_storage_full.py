"""A full disk under the file store (a real 2 MiB tmpfs): ``/readyz`` says so, uploads get 507.

The server runs on SQLite and PostgreSQL; the database lives outside the full file system.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import func, select

from league.http.routes.health import STORAGE_PROBE_MAX_AGE_S
from league.models import Model
from tests.diskfull import fill, small_tmpfs
from tests.league.conftest import Database, League, make_model_zip, start_league


@pytest.fixture(scope="module")
def full_league(database: Database, tmp_path_factory: pytest.TempPathFactory) -> Iterator[League]:
    """A running server whose file store is a small tmpfs (filled by the tests)."""
    data_dir = tmp_path_factory.mktemp("league") / "data"
    with small_tmpfs(data_dir / "files"):
        yield from start_league(database, data_dir)


def _readyz(league: League) -> tuple[int, dict]:
    time.sleep(STORAGE_PROBE_MAX_AGE_S + 0.1)  # past the cached probe answer
    with league.client() as client:
        response = client.get("/readyz")
    return response.status_code, response.json()


def _upload(league: League, seed: int) -> tuple[int, dict]:
    path = make_model_zip(league.models_dir, seed)
    with league.client("alice") as client:
        response = client.post("/api/models", files={"file": (path.name, path.read_bytes())})
    return response.status_code, response.json()


def _model_rows(league: League) -> int:
    with league.sessions() as session:
        return session.scalar(select(func.count(Model.id)))


def test_readyz_fails_while_the_file_store_cannot_take_a_write(full_league: League) -> None:
    assert _readyz(full_league) == (200, {"status": "ok"})
    filler = fill(full_league.settings.storage_dir)
    try:
        code, body = _readyz(full_league)
        assert code == 503 and body["status"] == "unavailable"
        assert "OSError: No space left on device" in body["detail"], body
    finally:
        filler.unlink()
    assert _readyz(full_league) == (200, {"status": "ok"})


def test_an_upload_to_a_full_disk_answers_507_and_leaves_nothing(full_league: League) -> None:
    rows = _model_rows(full_league)
    filler = fill(full_league.settings.storage_dir)
    try:
        code, body = _upload(full_league, seed=1)
        assert code == 507, body
        assert body["detail"].startswith("The server's file store is full; nothing was saved.")
        assert _model_rows(full_league) == rows
        assert full_league.storage.files("models") == []  # not even a temp file
    finally:
        filler.unlink()
    code, body = _upload(full_league, seed=1)
    assert code == 201, body
    stored: list[Path] = full_league.storage.files("models")
    assert [p.name for p in stored] == [f"{body['sha256']}.zip"]
