"""Failed uploads leave neither a row nor a file; stored files are content-addressed."""

from __future__ import annotations

import zipfile

import pytest
from sqlalchemy.orm import Session

from tests.league.conftest import UPLOAD_LIMIT, League, make_model_zip
from tests.league.helpers import model_rows, upload


def _files(league: League) -> list:
    return league.storage.files("models")


def test_refused_uploads_leave_nothing(league: League, tmp_path) -> None:
    rows, files = model_rows(league), _files(league)
    bad = tmp_path / "bad.zip"
    with zipfile.ZipFile(bad, "w") as zf:
        zf.writestr("model_metadata.json", "{not json")
    payloads = [bad.read_bytes(), b"PK\x03\x04garbage", b"", b"x" * (UPLOAD_LIMIT + 10)]
    with league.client("alice") as client:
        codes = [
            client.post("/api/models", files={"file": ("m.zip", payload)}).status_code
            for payload in payloads
        ]
    assert codes == [422, 422, 422, 413]  # refused by the validator; the last is too big
    assert model_rows(league) == rows and _files(league) == files


def test_failed_commit_removes_the_new_file(league: League, monkeypatch) -> None:
    rows, files = model_rows(league), _files(league)

    def broken_commit(self: Session) -> None:
        raise RuntimeError("disk full (simulated)")

    monkeypatch.setattr(Session, "commit", broken_commit)
    path = make_model_zip(league.models_dir, 201)
    with league.client("alice") as client:
        response = client.post("/api/models", files={"file": (path.name, path.read_bytes())})
    monkeypatch.undo()
    assert response.status_code == 500 and "logged" in response.json()["detail"]
    assert model_rows(league) == rows and _files(league) == files


def test_failed_commit_keeps_a_file_others_use(league: League, monkeypatch) -> None:
    bobs = upload(league, "bob", seed=202)
    files = _files(league)
    assert any(bobs["sha256"] in p.name for p in files)
    monkeypatch.setattr(Session, "commit", lambda self: (_ for _ in ()).throw(RuntimeError("x")))
    path = make_model_zip(league.models_dir, 202)
    with league.client("alice") as client:
        response = client.post("/api/models", files={"file": (path.name, path.read_bytes())})
    monkeypatch.undo()
    assert response.status_code == 500
    assert _files(league) == files


def test_same_file_two_owners_one_stored_file(league: League) -> None:
    a = upload(league, "alice", seed=203)
    b = upload(league, "bob", seed=203)
    assert a["id"] != b["id"] and a["sha256"] == b["sha256"]
    assert sum(a["sha256"] in p.name for p in _files(league)) == 1


@pytest.mark.parametrize("name", ["\x00bad", "x" * 65, "new\nline"])
def test_bad_model_names_are_refused(league: League, name: str) -> None:
    path = make_model_zip(league.models_dir, 204)
    with league.client("alice") as client:
        response = client.post(
            "/api/models", files={"file": (path.name, path.read_bytes())}, data={"name": name}
        )
    assert response.status_code == 422
