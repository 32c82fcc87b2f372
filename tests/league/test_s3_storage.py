"""The S3 object-storage backend against a real S3 endpoint: moto's standalone server, run
as a process with IAM checks on (a user with an access key, a bucket).

Without ``moto[server]`` (or if the server does not start) these tests skip; under
``CI=true`` they fail instead (``tests.prerequisites``).
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import boto3
import pytest
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from league import crud
from league.db import make_engine, make_session_factory
from league.jobs.worker import Worker
from league.migrations import upgrade
from league.models import Event, Job, Racer, TrainingJob
from league.schemas import EventCreate
from league.store import open_storage
from league.store.base import DigestMismatch, StorageError
from league.store.s3 import S3FileStore
from league.store.sweep import sweep
from submissions import validate
from tests.league.conftest import Database, make_model_zip, start_league
from tests.league.helpers import car, create_event, enter, race_result, upload
from tests.prerequisites import skip_or_fail

BUCKET = "slipstream-test"
REGION = "us-east-1"
START_S = 30.0
ALLOW_S3 = {
    "Version": "2012-10-17",
    "Statement": [{"Effect": "Allow", "Action": "s3:*", "Resource": "*"}],
}


@dataclass
class S3Server:
    """A running moto server: its endpoint and a user's credentials."""

    endpoint: str
    key_id: str
    secret: str

    def credentials(self, secret: str | None = None) -> dict[str, Any]:
        return {
            "aws_access_key_id": self.key_id,
            "aws_secret_access_key": secret or self.secret,
            "region_name": REGION,
        }

    def storage(self, prefix: str, bucket: str = BUCKET, secret: str | None = None) -> S3FileStore:
        """The backend on ``s3://bucket/prefix``."""
        url = f"s3://{bucket}/{prefix}"
        return S3FileStore(url, endpoint_url=self.endpoint, **self.credentials(secret))

    def keys(self, prefix: str) -> list[str]:
        """Every object key under ``prefix`` (read with the plain client)."""
        client = boto3.client("s3", endpoint_url=self.endpoint, **self.credentials())
        listing = client.list_objects_v2(Bucket=BUCKET, Prefix=prefix)
        return sorted(item["Key"] for item in listing.get("Contents", []))


def _wait_until_up(proc: subprocess.Popen, url: str, log: Path) -> None:
    deadline = time.monotonic() + START_S
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            skip_or_fail(f"moto server exited at start: {log.read_text()[-500:]}")
        try:
            urllib.request.urlopen(f"{url}/moto-api/", timeout=1).close()
            return
        except OSError:
            time.sleep(0.05)
    skip_or_fail(f"moto server did not answer within {START_S:.0f} s")


@pytest.fixture(scope="module")
def s3(tmp_path_factory: pytest.TempPathFactory) -> Iterator[S3Server]:
    """moto's S3 server on a free port: the first 3 requests (creating an IAM user with an
    access key) go unchecked, every later one must be signed by that user."""
    if importlib.util.find_spec("moto") is None or importlib.util.find_spec("flask") is None:
        skip_or_fail("moto[server] is not installed (pip install 'moto[server]')")
    from tests.league.conftest import free_port

    port, log = free_port(), tmp_path_factory.mktemp("moto") / "moto.log"
    env = {**os.environ, "INITIAL_NO_AUTH_ACTION_COUNT": "3"}
    args = [sys.executable, "-m", "moto.server", "-H", "127.0.0.1", "-p", str(port)]
    with log.open("wb") as out:
        proc = subprocess.Popen(args, env=env, stdout=out, stderr=subprocess.STDOUT)
    try:
        endpoint = f"http://127.0.0.1:{port}"
        started = time.monotonic()
        _wait_until_up(proc, endpoint, log)
        print(f"moto server up in {time.monotonic() - started:.2f} s")
        iam = boto3.client(
            "iam", endpoint_url=endpoint, region_name=REGION,
            aws_access_key_id="bootstrap", aws_secret_access_key="bootstrap",
        )  # fmt: skip
        iam.create_user(UserName="league")
        policy = json.dumps(ALLOW_S3)
        iam.put_user_policy(UserName="league", PolicyName="s3", PolicyDocument=policy)
        key = iam.create_access_key(UserName="league")["AccessKey"]
        server = S3Server(endpoint, key["AccessKeyId"], key["SecretAccessKey"])
        boto3.client("s3", endpoint_url=endpoint, **server.credentials()).create_bucket(
            Bucket=BUCKET
        )
        yield server
    finally:
        proc.terminate()
        proc.wait(timeout=10)


@pytest.fixture
def sessions(tmp_path: Path) -> Iterator[sessionmaker[Session]]:
    """A migrated, empty SQLite database."""
    engine = make_engine(f"sqlite:///{tmp_path / 'league.db'}")
    upgrade(engine)
    yield make_session_factory(engine)
    engine.dispose()


def test_put_read_round_trip_and_created_flag(s3: S3Server) -> None:
    storage = s3.storage("round-trip")
    sha256, created = storage.put("models", b"model bytes")
    assert created and sha256 == hashlib.sha256(b"model bytes").hexdigest()
    assert storage.put("models", b"model bytes") == (sha256, False)
    assert storage.read("models", sha256) == b"model bytes"
    assert s3.keys("round-trip/") == [f"round-trip/models/{sha256[:2]}/{sha256}.zip"]
    with pytest.raises(FileNotFoundError):
        storage.read("traces", sha256)
    storage.remove("models", sha256)
    assert s3.keys("round-trip/") == []


def test_a_tampered_object_fails_its_digest_check(s3: S3Server) -> None:
    storage = s3.storage("tampered")
    sha256, _ = storage.put("traces", b'{"trace": 1}')
    storage.client.put_object(Bucket=BUCKET, Key=storage.key("traces", sha256), Body=b"{}")
    with pytest.raises(DigestMismatch, match="does not match its sha256"):
        storage.read("traces", sha256)


@pytest.mark.parametrize(
    ("where", "expected"),
    [
        ("missing bucket", "bucket 'no-such-bucket' at http://127.0.0.1:\\d+ does not exist"),
        ("wrong secret", "rejected the credentials \\(SignatureDoesNotMatch"),
    ],
)
def test_bucket_and_credential_failures_are_storage_errors(
    s3: S3Server, where: str, expected: str
) -> None:
    if where == "missing bucket":
        storage = s3.storage("x", bucket="no-such-bucket")
    else:
        storage = s3.storage("x", secret="not-the-secret")
    with pytest.raises(StorageError, match=expected) as caught:
        storage.put("models", b"data")
    assert not caught.value.full  # the API answers 503, not 507
    with pytest.raises(StorageError, match=expected):
        storage.read("models", "0" * 64)
    problem = storage.write_problem()
    assert problem is not None and problem.startswith("the object store cannot take a write")


def test_an_unreachable_endpoint_is_a_storage_error() -> None:
    from tests.league.conftest import free_port

    endpoint = f"http://127.0.0.1:{free_port()}"
    storage = S3FileStore(
        f"s3://{BUCKET}", endpoint_url=endpoint, region_name=REGION,
        aws_access_key_id="k", aws_secret_access_key="s",
    )  # fmt: skip
    with pytest.raises(StorageError, match=f"cannot reach bucket '{BUCKET}' at {endpoint}"):
        storage.put("models", b"data")


def test_readiness_probe_writes_and_deletes_a_small_object(s3: S3Server) -> None:
    storage = s3.storage("probe")
    assert storage.write_problem(max_age=0) is None
    assert s3.keys("probe/") == []


def _reference(
    sessions: sessionmaker[Session], storage: S3FileStore, folder: Path
) -> tuple[str, str]:
    """A model row and a race row referring to stored files; their sha256s."""
    data = make_model_zip(folder, seed=3).read_bytes()
    with sessions() as session:
        owner, _ = crud.create_racer(session, "carol")
        model, _ = crud.add_model(session, storage, owner, "kept", data, validate(data).info)
        event = crud.create_event(session, EventCreate(name="Sweep Cup"), None)
        event = session.get_one(Event, event.id)
        race = crud.record_race(session, storage, event, race_result(event, [car("bot0")]), {})
        assert race.trace_sha256 is not None
        return model.sha256, race.trace_sha256


def test_sweep_removes_only_old_unreferenced_objects(
    s3: S3Server, sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    storage = s3.storage("sweep")
    model_sha, trace_sha = _reference(sessions, storage, tmp_path)
    run_sha = storage.put("runs", b"a training run's folder, zipped")[0]
    with sessions() as session:  # a training job's run, kept
        owner = session.scalars(select(Racer)).first()
        job = TrainingJob(owner_id=owner.id, name="run", spec={}, reward_source="", minutes=1)
        job.status, job.run_sha256 = "done", run_sha
        session.add(job)
        session.commit()
    orphans = [storage.put(kind, b"no row")[0] for kind in ("models", "traces", "runs")]
    stray, stale_probe = "sweep/models/README", "sweep/.tmp-probe-left-behind"
    for key in (stray, stale_probe):
        storage.client.put_object(Bucket=BUCKET, Key=key, Body=b"x")
    everything = set(s3.keys("sweep/"))

    report = sweep(sessions, storage, grace_s=600)  # all younger than the grace period
    assert (report.temp, report.unreferenced) == (0, dict.fromkeys(("models", "traces", "runs"), 0))
    assert set(s3.keys("sweep/")) == everything

    report = sweep(sessions, storage, grace_s=600, now=time.time() + 601)
    assert (report.temp, report.unreferenced) == (1, {"models": 1, "traces": 1, "runs": 1})
    kinds = ("models", "traces", "runs")
    gone = {storage.key(kind, sha) for kind, sha in zip(kinds, orphans, strict=True)}
    assert set(s3.keys("sweep/")) == everything - gone - {stale_probe}
    assert storage.read("models", model_sha) and storage.read("traces", trace_sha)
    assert storage.read("runs", run_sha) == b"a training run's folder, zipped"


def test_an_orphan_stored_again_or_wanted_meanwhile_is_kept(
    s3: S3Server, sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    storage = s3.storage("again")
    _reference(sessions, storage, tmp_path)
    sha256, _ = storage.put("models", b"uploaded again")
    first = storage.client.head_object(Bucket=BUCKET, Key=storage.key("models", sha256))
    time.sleep(1.1)  # LastModified counts whole seconds
    assert storage.put("models", b"uploaded again") == (sha256, False)  # refreshes it
    stored_at = first["LastModified"].timestamp() + 0.5
    sweep(sessions, storage, grace_s=600, now=stored_at + 600)
    assert storage.read("models", sha256) == b"uploaded again"
    # a row that commits while the sweep holds the bytes: they are written back
    assert not storage.remove_orphan("models", sha256, time.time() + 60, lambda: True)
    assert storage.read("models", sha256) == b"uploaded again"
    sweep(sessions, storage, grace_s=600, now=time.time() + 601)
    with pytest.raises(FileNotFoundError):
        storage.read("models", sha256)


@pytest.fixture
def s3_env(s3: S3Server) -> Iterator[None]:
    """The standard AWS variables a league process reads its credentials from."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("AWS_ACCESS_KEY_ID", s3.key_id)
        patch.setenv("AWS_SECRET_ACCESS_KEY", s3.secret)
        patch.setenv("AWS_REGION", REGION)
        for name in ("AWS_SESSION_TOKEN", "AWS_PROFILE"):
            patch.delenv(name, raising=False)
        yield


def test_a_league_on_object_storage_stores_models_and_traces_there(
    s3: S3Server, s3_env: None, database: Database, tmp_path: Path
) -> None:
    prefix = f"league-{database.backend}"
    data_dir = tmp_path / "data"
    options = {"storage_url": f"s3://{BUCKET}/{prefix}", "s3_endpoint_url": s3.endpoint}
    for league in start_league(database, data_dir, **options):
        assert isinstance(open_storage(league.settings), S3FileStore)
        model = upload(league, "alice", seed=1)
        model_sha = hashlib.sha256(make_model_zip(league.models_dir, 1).read_bytes()).hexdigest()
        event = create_event(league, name="Bucket Cup", laps=1, time_limit_s=20.0, seeds=[0])
        enter(league, "alice", event["id"], model["id"])
        worker = Worker(league.settings, "s3-worker")
        while worker.run_once():
            pass
        worker.engine.dispose()
        with league.client() as client:
            assert client.get("/readyz").json() == {"status": "ok"}
            (race,) = client.get("/api/races", params={"event": event["id"]}).json()
            trace = client.get(f"/api/races/{race['id']}/trace")
        assert trace.status_code == 200, trace.text
        trace_sha = hashlib.sha256(trace.content).hexdigest()
        assert s3.keys(f"{prefix}/") == [
            f"{prefix}/models/{model_sha[:2]}/{model_sha}.zip",
            f"{prefix}/traces/{trace_sha[:2]}/{trace_sha}.json",
        ]
    assert not (data_dir / "files").exists()  # nothing went to the local data directory


def test_a_league_whose_bucket_is_missing_answers_503(
    s3: S3Server, s3_env: None, tmp_path: Path
) -> None:
    database = Database(f"sqlite:///{tmp_path / 'league.db'}", "sqlite")
    options = {"storage_url": "s3://no-such-bucket/league", "s3_endpoint_url": s3.endpoint}
    for league in start_league(database, tmp_path / "data", **options):
        path = make_model_zip(league.models_dir, seed=2)
        with league.client("alice") as client:
            response = client.post("/api/models", files={"file": (path.name, path.read_bytes())})
            ready = client.get("/readyz")
        assert response.status_code == 503 and response.headers["Retry-After"] == "60"
        assert ready.status_code == 503 and "does not exist" in ready.json()["detail"]


def test_a_worker_that_cannot_reach_the_store_requeues_the_job(
    s3: S3Server, s3_env: None, tmp_path: Path
) -> None:
    """An object store down for a moment is not a bad model: the job runs once it is back."""
    database = Database(f"sqlite:///{tmp_path / 'league.db'}", "sqlite")
    options = {"storage_url": f"s3://{BUCKET}/requeue", "s3_endpoint_url": s3.endpoint}
    for league in start_league(database, tmp_path / "data", **options):
        model = upload(league, "alice", seed=3)
        event = create_event(league, name="Outage Cup", laps=1, time_limit_s=10.0, seeds=[0])
        enter(league, "alice", event["id"], model["id"])
        unreachable = league.settings.model_copy(update={"s3_endpoint_url": "http://127.0.0.1:9"})
        cut_off = Worker(unreachable, "cut-off-worker")
        assert cut_off.run_once()
        cut_off.engine.dispose()
        with make_session_factory(make_engine(database.url))() as session:
            (job,) = session.query(Job).all()
            assert job.status == "queued" and "could not read a model file" in (job.error or "")
        worker = Worker(league.settings, "s3-worker")
        while worker.run_once():
            pass
        worker.engine.dispose()
        with league.client() as client:
            assert len(client.get("/api/races", params={"event": event["id"]}).json()) == 1
