"""The server's start-up sweep: stale temp files and files no row refers to go; files in
use, and anything younger than the grace period (maybe another process's write), stay."""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from league import crud
from league.db import make_engine, make_session_factory
from league.migrations import upgrade
from league.models import Event, TrainingJob
from league.schemas import EventCreate
from league.settings import Settings
from league.store.local import LocalFileStore
from league.store.sweep import sweep
from submissions import validate
from tests.league.conftest import Database, League, make_model_zip, start_league
from tests.league.helpers import car, race_result

HOUR = 3600.0


def _age(path: Path, seconds: float) -> Path:
    """Set ``path``'s mtime ``seconds`` into the past."""
    then = time.time() - seconds
    os.utime(path, (then, then))
    return path


def _orphan(storage: LocalFileStore, kind: str, content: bytes) -> Path:
    """A stored-looking file that no row refers to."""
    path = storage.path(kind, hashlib.sha256(content).hexdigest())
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(content)
    return path


def _referenced(database: Database, data_dir: Path) -> tuple[Path, Path, Path]:
    """A model file with its row, a trace file with its race and a training run's zip with
    its job, before the server runs."""
    settings = Settings(data_dir=data_dir, database_url=database.url)
    engine = make_engine(settings.db_url)
    upgrade(engine)
    storage = LocalFileStore(settings.storage_dir)
    with make_session_factory(engine)() as session:
        owner, _ = crud.create_racer(session, "carol")
        data = make_model_zip(data_dir.parent / "uploads", seed=7).read_bytes()
        model, _ = crud.add_model(session, storage, owner, "kept", data, validate(data).info)
        event = crud.create_event(session, EventCreate(name="Sweep Cup"), None)
        event = session.get_one(Event, event.id)
        race = crud.record_race(session, storage, event, race_result(event, [car("bot0")]), {})
        run_sha, _ = storage.put("runs", b"a run folder's zip")
        session.add(
            TrainingJob(
                owner_id=owner.id, name="kept", spec={}, reward_source="", minutes=1,
                status="done", run_sha256=run_sha,
            )
        )  # fmt: skip
        session.commit()
        paths = (
            storage.path("models", model.sha256),
            storage.path("traces", race.trace_sha256),
            storage.path("runs", run_sha),
        )
    engine.dispose()
    return paths


def _temp(folder: Path, name: str) -> Path:
    """A leftover temp file (a write killed half way)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_bytes(b"partial")
    return path


@pytest.fixture(scope="module")
def swept(
    database: Database, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[tuple[League, dict[str, Path]]]:
    """A store seeded with leftovers of every kind, then a server started on it."""
    data_dir = tmp_path_factory.mktemp("league") / "data"
    storage = LocalFileStore(data_dir / "files")
    model_file, trace_file, run_file = _referenced(database, data_dir)
    files = {
        "stale temp": _age(_temp(model_file.parent, ".tmp-k1ll3d"), HOUR),
        "fresh temp": _temp(trace_file.parent, ".tmp-writing"),
        "stale probe": _age(_temp(storage.root, ".tmp-probe-abc"), HOUR),
        "stale model orphan": _age(_orphan(storage, "models", b"no row"), HOUR),
        "fresh model orphan": _orphan(storage, "models", b"row being written"),
        "stale trace orphan": _age(_orphan(storage, "traces", b"no race"), HOUR),
        "stale run orphan": _age(_orphan(storage, "runs", b"no training job"), HOUR),
        "referenced model": _age(model_file, HOUR),
        "referenced run": _age(run_file, HOUR),
        "referenced trace": _age(trace_file, HOUR),
        "stray name": _age(_temp(model_file.parent, "README"), HOUR),
    }
    for league in start_league(database, data_dir):
        yield league, files


def test_start_up_removes_only_stale_leftovers(swept: tuple[League, dict[str, Path]]) -> None:
    _, files = swept
    left = {name for name, path in files.items() if path.exists()}
    gone = {"stale temp", "stale probe", "stale model orphan", "stale trace orphan"}
    gone |= {"stale run orphan"}
    assert left == set(files) - gone


def test_referenced_files_still_serve(swept: tuple[League, dict[str, Path]]) -> None:
    league, _ = swept
    with league.client() as client:
        race_id = client.get("/api/races").json()[0]["id"]
        assert client.get(f"/api/races/{race_id}/trace").status_code == 200


def test_a_file_stored_again_during_the_grace_period_is_kept(
    swept: tuple[League, dict[str, Path]],
) -> None:
    league, _ = swept
    old = _age(_orphan(league.storage, "models", b"uploaded again"), HOUR)
    assert league.storage.put("models", b"uploaded again")[1] is False  # refreshes its mtime
    grace = league.settings.orphan_grace_seconds
    sweep(league.sessions, league.storage, grace)
    assert old.exists()
    sweep(league.sessions, league.storage, grace, now=time.time() + grace + 1)
    assert not old.exists()  # still no row: it goes once the grace period is over


def test_a_database_that_refers_to_no_files_sweeps_none(tmp_path: Path) -> None:
    engine = make_engine(f"sqlite:///{tmp_path / 'empty.db'}")  # the wrong, empty database
    upgrade(engine)
    storage = LocalFileStore(tmp_path / "files")
    kinds = ("models", "traces", "runs")
    files = [_age(_orphan(storage, kind, b"a file"), HOUR) for kind in kinds]
    report = sweep(make_session_factory(engine), storage, grace_s=600)
    engine.dispose()
    assert all(path.exists() for path in files)
    assert report.unreferenced == dict.fromkeys(kinds, 0)
