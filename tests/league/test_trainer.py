"""Real trainer processes against a real server: a one-minute job ends with a model that
races; a trainer killed with SIGKILL leaves nothing running and another trainer finishes
its job, which is then resumed (on SQLite); a reward that reaches for the network
mid-training fails its job with the reason (on SQLite and PostgreSQL)."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from arena import make_config
from arena.race import run_race
from league.models import Model, TrainingJob
from league.training.sandbox import probe
from league.training.trainer import job_file, race_poses
from submissions import load_policy
from tests.league.conftest import Database, League, start_league
from tests.league.helpers import start_daemon

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        probe() is not None and os.environ.get("CI") != "true",
        reason=f"this host cannot sandbox training jobs: {probe()} (CI installs bubblewrap)",
    ),
]
LEASE_SECONDS = 4.0
JOB = {
    "name": "trained-on-the-server",
    "reward_source": (
        "def reward_function(params):\n"
        "    return 1.0 - 2.0 * params['distance_from_center'] / params['track_width']\n"
    ),
    "recipe": "time_trial",
    "options": {"track": "slipstream_speedway"},
    "minutes": 0.75,
}


@pytest.fixture(scope="module")
def league(database: Database, tmp_path_factory: pytest.TempPathFactory) -> Iterator[League]:
    yield from start_league(
        database,
        tmp_path_factory.mktemp("league") / "data",
        lease_seconds=LEASE_SECONDS,
        training_workers=1,
    )


def _trainer(league: League, name: str, log: Path) -> subprocess.Popen:
    return start_daemon(
        league,
        "league.training.trainer",
        [name],
        log,
        SLIPSTREAM_LEASE_SECONDS=str(LEASE_SECONDS),
        SLIPSTREAM_TRAINING_WORKERS="1",
    )


def _wait_for(league: League, job_id: int, done, timeout: float) -> TrainingJob:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with league.sessions() as session:
            job = session.get_one(TrainingJob, job_id)
            if done(job):
                session.expunge(job)
                return job
        time.sleep(0.5)
    raise AssertionError(f"training job {job_id} never got there")


def _train_to_end(
    league: League, job_id: int, name: str, tmp_path: Path, timeout: float
) -> TrainingJob:
    """Start a trainer (its log in ``tmp_path/NAME.log``) until ``job_id`` has ended."""
    trainer = _trainer(league, name, tmp_path / f"{name}.log")
    try:
        return _wait_for(league, job_id, lambda j: j.status not in ("queued", "running"), timeout)
    finally:
        trainer.send_signal(signal.SIGTERM)
        trainer.wait(30)


def _job_processes(marker: str) -> list[str]:
    found = subprocess.run(["pgrep", "-af", marker], capture_output=True, text=True)
    return [line for line in found.stdout.splitlines() if "pgrep" not in line]


def test_a_killed_trainers_job_is_finished_by_another_and_its_model_races(
    league: League, tmp_path: Path
) -> None:
    if league.backend == "postgres":  # the minutes it costs buy nothing new there
        pytest.skip(
            "the killed-trainer and resume runs go on SQLite; on PostgreSQL the failing-reward "
            "job runs a trainer end to end, and test_training_queue covers the queue"
        )
    with league.client("alice") as alice:
        created = alice.post("/api/training-jobs", json=JOB)
        assert created.status_code == 201, created.text
        job_id = created.json()["id"]
        first = _trainer(league, "first", tmp_path / "first.log")
        try:
            _wait_for(league, job_id, lambda j: j.status == "running", 60)
            time.sleep(8)  # the child is training
            assert _job_processes(f"training/jobs/{job_id}-1")
            first.send_signal(signal.SIGKILL)
            first.wait()
            time.sleep(1)
            assert _job_processes(f"training/jobs/{job_id}-1") == []  # died with its trainer
        finally:
            first.kill()
        job = _train_to_end(league, job_id, "second", tmp_path, 240)
        log = (tmp_path / "second.log").read_text()
        assert job.status == "done", f"{job.error}\n{log[-3000:]}"
        assert job.attempts == 2 and job.model_id is not None and job.run_sha256
        metrics = alice.get(f"/api/training-jobs/{job_id}/metrics").json()
        assert metrics  # iterations of both attempts (one, when the machine is busy)
        logs = alice.get(f"/api/training-jobs/{job_id}/logs").text
        assert "[running]" in logs and "lease expired" in logs
        run = alice.get(f"/api/training-jobs/{job_id}/run.zip")
        assert run.status_code == 200 and run.content[:2] == b"PK"
    resumed = _resume(league, job_id, metrics[-1]["iteration"], tmp_path)
    assert resumed.model_id is not None and resumed.model_id != job.model_id
    with league.sessions() as session:
        model = session.get_one(Model, job.model_id)
        assert model.name == JOB["name"] and model.owner_id == league.ids["alice"]
        data = league.storage.read("models", model.sha256)
    archive = tmp_path / "model.zip"
    archive.write_bytes(data)
    policy = load_policy(archive)
    config = make_config(
        track="slipstream_speedway",
        sensors=policy.info.sensors,
        action_space=policy.info.action_space,
        stack_size=policy.info.stack_size,  # the time_trial recipe's two frames
    )
    config = config.model_copy(update={"laps": 1, "time_limit_s": 10.0})
    raced = run_race(config, {"car0": policy})
    assert raced.car("car0").distance > 5.0  # it drives


def _resume(league: League, job_id: int, last_iteration: int, tmp_path: Path) -> TrainingJob:
    """Resume ``job_id`` for a few seconds on a fresh trainer: its iterations go on from
    ``last_iteration``, and it ends with a model of its own."""
    with league.client("alice") as alice:
        body = {"name": "resumed", "resume_of": job_id, "minutes": 0.25}
        refused = alice.post("/api/training-jobs", json={**body, "options": {"seed": 3}})
        assert refused.status_code == 422 and "keeps its settings" in refused.text
        created = alice.post("/api/training-jobs", json=body)
        assert created.status_code == 201, created.text
        resumed_id = created.json()["id"]
        assert created.json()["resume_of"] == job_id and created.json()["clone_of"] is None
        resumed = _train_to_end(league, resumed_id, "resumer", tmp_path, 180)
        assert resumed.status == "done", resumed.error
        metrics = alice.get(f"/api/training-jobs/{resumed_id}/metrics").json()
        assert metrics[0]["iteration"] == last_iteration + 1
    return resumed


def test_a_reward_that_reaches_out_mid_training_fails_its_job(
    league: League, tmp_path: Path
) -> None:
    reward = (
        "import socket\n"
        "def reward_function(params):\n"
        "    if params['steps'] > 30:\n"
        "        socket.create_connection(('127.0.0.1', 5432), timeout=2)\n"
        "    return 1.0\n"
    )
    body = {**JOB, "reward_source": reward, "recipe": None}
    with league.client("bob") as bob:
        created = bob.post("/api/training-jobs", json=body)
        assert created.status_code == 201, created.text
        job_id = created.json()["id"]
        job = _train_to_end(league, job_id, "third", tmp_path, 120)
    assert job.status == "failed" and job.model_id is None
    assert "ConnectionRefusedError" in job.error or "unreachable" in job.error, job.error


def test_links_a_job_plants_do_not_make_the_trainer_read_host_files(tmp_path: Path) -> None:
    run = tmp_path / "job" / "run"
    (run / "model").mkdir(parents=True)
    secret = tmp_path / "secret.zip"
    secret.write_bytes(b"PK not the job's")
    (run / "model" / "model.zip").symlink_to(secret)
    (run / "0").symlink_to(tmp_path)  # a folder link on the way to the simtrace
    (tmp_path / "training-simtrace").mkdir()
    (tmp_path / "training-simtrace" / "0-iteration.csv").write_text("episode,X,Y,yaw\n0,1,2,3\n")
    assert job_file(tmp_path / "job", "run", "model", "model.zip") is None
    assert race_poses(run, 0) is None
    (run / "model" / "model.zip").unlink()
    (run / "model" / "model.zip").write_bytes(b"PK the job's own")
    assert job_file(tmp_path / "job", "run", "model", "model.zip") is not None
