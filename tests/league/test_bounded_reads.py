"""Reads bounded by construction: a metrics reply, a user track, and error texts that show
neither the server's paths nor other racers' tracks (issue 34, rows 2, 7 and 12)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from arena.actions import default_discrete_space
from league import crud
from league.models import Racer
from submissions import pack, validate
from submissions.format import Limits
from tests.league.conftest import CREATED_AT, League, policy_onnx
from tracks import catalog
from tracks.catalog import get_track
from tracks.io import write_document

MAX_POINTS = 500


def _wide_csv(columns: int, rows: int, seed: int) -> str:
    """A metrics file as a hostile racer writes it: many columns of small random numbers."""
    digits = np.random.default_rng(seed).integers(0, 10, size=(rows, columns))
    header = ",".join(f"c{i}" for i in range(columns))
    return header + "\n" + "".join(",".join(map(str, row)) + "\n" for row in digits.tolist())


def _archive(folder: Path, metrics: str, seed: int) -> bytes:
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / f"metrics-{seed}.zip"
    space = default_discrete_space()
    pack(out, policy_onnx(seed), space, ["lidar"], metrics_csv=metrics, created_at=CREATED_AT)
    return out.read_bytes()


def test_a_metrics_file_with_too_many_columns_is_refused_at_upload(
    league: League, tmp_path: Path
) -> None:
    data = _archive(tmp_path, _wide_csv(500, 200, seed=1), seed=9101)
    assert len(data) < league.settings.max_upload_bytes
    with league.client("alice") as alice:
        response = alice.post("/api/models", files={"file": ("wide.zip", data)})
    assert response.status_code == 422, response.text
    problem = response.json()["problems"][0]
    assert problem["field"] == "archive:metrics.csv"
    assert "too many columns" in problem["message"]
    assert problem["expected"] == "at most 64 columns"


def test_a_long_metrics_file_is_answered_downsampled(league: League, tmp_path: Path) -> None:
    """20,000 rows of 17 columns: at most 500 points a column, the last one the file's last."""
    rows = 20_000
    metrics = "iteration,mean_reward," + ",".join(f"m{i}" for i in range(15)) + "\n"
    metrics += "".join(
        f"{i},{i * 0.5}," + ",".join(str(i % (k + 2)) for k in range(15)) + "\n"
        for i in range(rows)
    )
    data = _archive(tmp_path, metrics, seed=9102)
    with league.client("alice") as alice:
        model = alice.post("/api/models", files={"file": ("long.zip", data)})
        assert model.status_code == 201, model.text
        reply = alice.get(f"/api/models/{model.json()['id']}/metrics")
    assert reply.status_code == 200
    body = reply.json()
    assert body["rows"] == rows and len(body["columns"]) == 17
    assert all(len(values) == MAX_POINTS for values in body["values"].values())
    iterations = body["values"]["iteration"]
    assert iterations == sorted(iterations) and iterations[-1] == rows - 1
    assert body["values"]["mean_reward"][-1] == (rows - 1) * 0.5
    assert len(reply.content) < 200_000


def test_metrics_stored_before_the_bounds_are_answered_small(
    league: League, tmp_path: Path
) -> None:
    """A 500 x 2,000 file stored by an older server: the reply is cut to 64 x 500."""
    data = _archive(tmp_path, _wide_csv(500, 2_000, seed=2), seed=9103)
    lax = Limits(max_metrics_columns=1_000)
    report = validate(data, lax, run_policy=False)
    assert report.info is not None, report.problems
    with league.sessions() as session:
        owner = session.get(Racer, league.ids["alice"])
        model, _ = crud.add_model(session, league.storage, owner, "old-wide", data, report.info)
        model_id = model.id
    with league.client("alice") as alice:
        reply = alice.get(f"/api/models/{model_id}/metrics")
    assert reply.status_code == 200
    body = reply.json()
    assert body["columns"] == [f"c{i}" for i in range(64)] and body["rows"] == 2_000
    assert all(len(values) == MAX_POINTS for values in body["values"].values())
    assert len(reply.content) < 200_000


@pytest.fixture
def home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A fresh SLIPSTREAM_HOME: the server (same process) finds user tracks there."""
    monkeypatch.setenv("SLIPSTREAM_HOME", str(tmp_path / "home"))
    return tmp_path / "home"


def _user_track(home: Path, name: str) -> Path:
    folder = home / "tracks"
    folder.mkdir(parents=True, exist_ok=True)
    path = write_document(get_track("grand_tour"), folder / f"{name}.json")
    doc = json.loads(path.read_text())
    doc["name"] = name
    path.write_text(json.dumps(doc))
    return path


def test_a_user_track_is_checked_once_not_on_every_request(
    league: League, home: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _user_track(home, "their_loop")
    checks = []
    real = catalog.read_document
    monkeypatch.setattr(catalog, "read_document", lambda path: checks.append(path) or real(path))
    with league.client() as anonymous:
        answers = [
            anonymous.get("/api/tracks/their_loop", params={"direction": d})
            for d in ("ccw", "cw") * 10
        ]
    assert {a.status_code for a in answers} == {200}
    assert answers[0].json()["name"] == "their_loop"
    assert len(checks) == 1


def test_a_track_read_is_revalidated_and_follows_its_file(league: League, home: Path) -> None:
    path = _user_track(home, "their_loop")
    with league.client() as anonymous:
        first = anonymous.get("/api/tracks/their_loop")
        again = anonymous.get(
            "/api/tracks/their_loop", headers={"If-None-Match": first.headers["etag"]}
        )
        doc = json.loads(path.read_text())
        doc["display_name"] = "Their Loop, resurfaced"
        path.write_text(json.dumps(doc))
        changed = anonymous.get(
            "/api/tracks/their_loop", headers={"If-None-Match": first.headers["etag"]}
        )
        path.unlink()
        gone = anonymous.get("/api/tracks/their_loop")
    assert first.status_code == 200 and again.status_code == 304
    assert changed.status_code == 200
    assert changed.json()["display_name"] == "Their Loop, resurfaced"
    assert changed.headers["etag"] != first.headers["etag"]
    assert gone.status_code == 404


def test_event_errors_show_no_server_path_and_no_other_users_tracks(
    league: League, home: Path
) -> None:
    _user_track(home, "secret_loop")
    broken = home / "tracks" / "broken_loop.json"
    broken.write_text('{"name": "broken_loop", "centerline": [[0, 0], [1, 0]')
    with league.client("admin") as admin:
        on_broken = admin.post("/api/events", json={"name": "Cup", "track": "broken_loop"})
        on_unknown = admin.post("/api/events", json={"name": "Cup", "track": "atlantis"})
        read_broken = admin.get("/api/tracks/broken_loop")
        read_unknown = admin.get("/api/tracks/atlantis")
    assert on_broken.status_code == 422 and on_unknown.status_code == 422
    broken_text = on_broken.json()["detail"]
    assert "broken_loop" in broken_text
    assert str(home) not in broken_text and ".json" not in broken_text
    assert read_broken.status_code == 404 and read_unknown.status_code == 404
    assert str(home) not in read_broken.json()["detail"]
    assert "secret_loop" not in read_unknown.json()["detail"]
    unknown_text = on_unknown.json()["detail"]
    assert "atlantis" in unknown_text and "grand_tour" in unknown_text
    assert "secret_loop" not in unknown_text and "broken_loop" not in unknown_text
