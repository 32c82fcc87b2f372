"""``/api/training-jobs/{id}/checkpoints``: a stored run's checkpoints listed, and one made
a model after the upload validator accepts it; a run's folder is the racer's code's output,
so a lying index or a broken archive is refused without a model."""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from league.models import Model, TrainingJob
from league.training.checkpoints import CheckpointOut
from tests.league.conftest import Database, League, make_model_zip, start_league

KEPT = [
    CheckpointOut(
        name="best", by="completion", iteration=4, minutes=1.5, completion=100.0, best_lap=12.4
    ),
    CheckpointOut(
        name="fastest", by="lap", iteration=2, minutes=0.9, completion=100.0, best_lap=10.8
    ),
    CheckpointOut(name="last", by="last", iteration=6, minutes=2.0),
]


def run_zip(members: dict[str, bytes]) -> bytes:
    """A run zip holding ``members`` (name -> bytes)."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return buffer.getvalue()


def checkpoint_index(kept: list[CheckpointOut]) -> bytes:
    return json.dumps([{**c.model_dump(), "file": f"{c.name}.zip"} for c in kept]).encode()


def _job(league: League, name: str, members: dict[str, bytes] | None) -> int:
    """A done job of alice's whose stored run holds ``members`` (None: no stored run)."""
    sha = league.storage.put("runs", run_zip(members))[0] if members is not None else None
    with league.sessions() as session:
        job = TrainingJob(
            owner_id=league.ids["alice"],
            name=name,
            status="done",
            spec={"options": {"track": "slipstream_speedway"}},
            reward_source="def reward_function(params):\n    return 1.0\n",
            minutes=2.0,
            run_sha256=sha,
        )
        session.add(job)
        session.commit()
        return job.id


@pytest.fixture(scope="module")
def league(tmp_path_factory: pytest.TempPathFactory) -> Iterator[League]:
    """SQLite only: these routes read one job and one model query; what they exercise is
    reading an untrusted run zip and the upload validator."""
    folder = tmp_path_factory.mktemp("checkpoints-league")
    database = Database(f"sqlite:///{folder / 'league.db'}", "sqlite")
    yield from start_league(database, folder / "data")


@pytest.fixture(scope="module")
def archives(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """Three valid submissions, one per checkpoint, each of its own weights."""
    folder = tmp_path_factory.mktemp("checkpoint-archives")
    return {c.name: make_model_zip(folder, seed).read_bytes() for seed, c in enumerate(KEPT)}


def _members(archives: dict[str, bytes]) -> dict[str, bytes]:
    return {
        "metrics.csv": b"iteration\n0\n",
        "models/index.json": checkpoint_index(KEPT),
        **{f"models/{name}.zip": data for name, data in archives.items()},
    }


def test_a_run_s_checkpoints_are_listed_and_the_fastest_becomes_a_model_once(
    league: League, archives: dict[str, bytes]
) -> None:
    job_id = _job(league, "sprinter", _members(archives))
    with league.client("alice") as client:
        listed = client.get(f"/api/training-jobs/{job_id}/checkpoints")
        assert listed.status_code == 200, listed.text
        assert [(c["name"], c["iteration"], c["best_lap"]) for c in listed.json()] == [
            ("best", 4, 12.4),
            ("fastest", 2, 10.8),
            ("last", 6, None),
        ]
        assert all(c["model_id"] is None for c in listed.json())

        made = client.post(f"/api/training-jobs/{job_id}/checkpoints/fastest/model")
        assert made.status_code == 201, made.text
        model = made.json()
        assert model["name"] == "sprinter-fastest" and model["owner"] == "alice"
        again = client.post(f"/api/training-jobs/{job_id}/checkpoints/fastest/model")
        assert (again.status_code, again.json()["id"]) == (200, model["id"])

        by_name = {
            c["name"]: c for c in client.get(f"/api/training-jobs/{job_id}/checkpoints").json()
        }
        assert by_name["fastest"]["model_id"] == model["id"]
        assert by_name["best"]["model_id"] is None
    assert league.storage.read("models", model["sha256"]) == archives["fastest"]


def test_another_racer_cannot_read_or_take_a_job_s_checkpoints(
    league: League, archives: dict[str, bytes]
) -> None:
    job_id = _job(league, "private", _members(archives))
    with league.client("bob") as client:
        assert client.get(f"/api/training-jobs/{job_id}/checkpoints").status_code == 404
        taken = client.post(f"/api/training-jobs/{job_id}/checkpoints/best/model")
        assert taken.status_code == 404
        assert client.get("/api/models").json() == []


def test_a_job_without_a_stored_run_or_checkpoints_offers_none(
    league: League, archives: dict[str, bytes]
) -> None:
    running = _job(league, "still-running", None)
    old = _job(league, "before-checkpoints", {"model/model.zip": archives["best"]})
    with league.client("alice") as client:
        for job_id in (running, old):
            assert client.get(f"/api/training-jobs/{job_id}/checkpoints").json() == []
            missing = client.post(f"/api/training-jobs/{job_id}/checkpoints/last/model")
            assert missing.status_code == 404, missing.text
        unknown = client.post(f"/api/training-jobs/{old}/checkpoints/worst/model")
        assert unknown.status_code == 422


def _model_count(league: League) -> int:
    with league.sessions() as session:
        return session.query(Model).count()


def test_a_lying_index_or_a_broken_archive_is_refused_without_a_model(
    league: League, archives: dict[str, bytes], tmp_path: Path
) -> None:
    before = _model_count(league)
    unlisted = _job(
        league, "unlisted", {"models/index.json": checkpoint_index(KEPT)}
    )  # no archives
    garbage_index = _job(league, "garbage-index", {"models/index.json": b"[{'name': 1}]"})
    bomb = {
        "models/index.json": checkpoint_index(KEPT[:1]),
        "models/best.zip": b"\0" * (league.settings.max_upload_bytes + 1),
    }
    broken = {
        "models/index.json": checkpoint_index(KEPT[2:]),
        "models/last.zip": b"not a zip at all",
    }
    too_large, not_a_model = _job(league, "bomb", bomb), _job(league, "broken", broken)
    with league.client("alice") as client:
        assert client.get(f"/api/training-jobs/{unlisted}/checkpoints").json() == []
        unreadable = client.get(f"/api/training-jobs/{garbage_index}/checkpoints")
        assert unreadable.status_code == 422
        assert "checkpoint index is unreadable" in unreadable.json()["detail"]
        big = client.post(f"/api/training-jobs/{too_large}/checkpoints/best/model")
        assert big.status_code == 422 and "over the limit" in big.json()["detail"]
        refused = client.post(f"/api/training-jobs/{not_a_model}/checkpoints/last/model")
        assert refused.status_code == 422 and refused.json()["problems"]
    assert _model_count(league) == before
