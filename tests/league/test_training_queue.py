"""The training queue on SQLite and PostgreSQL: leases honour the running quotas and
priorities, two trainers never hold one job, a dead trainer's job returns or fails, and a
trainer whose lease moved on cannot report or finish."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from datetime import timedelta

import pytest
from sqlalchemy import update
from sqlalchemy.orm import Session, sessionmaker

from league import crud
from league.db import make_engine, make_session_factory
from league.migrations import upgrade
from league.models import TrainingEvent, TrainingJob, utcnow
from league.settings import Settings
from league.training.queue import (
    expire_training_leases,
    finish_training,
    heartbeat_training,
    lease_training,
    report,
    request_stop,
)
from tests.league.conftest import Database


@pytest.fixture
def sessions(database: Database) -> Iterator[sessionmaker[Session]]:
    engine = make_engine(database.url)
    upgrade(engine)
    factory = make_session_factory(engine)
    with factory() as session:
        session.query(TrainingJob).delete()
        session.commit()
    yield factory
    engine.dispose()


def _racer(sessions: sessionmaker[Session], alias: str) -> int:
    with sessions() as session:
        return crud.create_racer(session, alias)[0].id


def _job(sessions: sessionmaker[Session], owner: int, priority: int = 0) -> int:
    with sessions() as session:
        job = TrainingJob(
            owner_id=owner, name="car", spec={}, reward_source="", minutes=1, priority=priority
        )
        session.add(job)
        session.commit()
        return job.id


def _settings(total: int = 2, per_racer: int = 1) -> Settings:
    return Settings(training_jobs_total=total, training_jobs_per_racer=per_racer)


def _lease(sessions: sessionmaker[Session], settings: Settings, name: str = "t"):
    with sessions() as session:
        return lease_training(session, settings, name, 30)


def test_leases_honour_the_running_quotas_and_priority(sessions) -> None:
    alice, bob, carol = (_racer(sessions, a) for a in ("qa_alice", "qa_bob", "qa_carol"))
    a1, a2 = _job(sessions, alice), _job(sessions, alice)
    b1 = _job(sessions, bob)
    c1 = _job(sessions, carol, priority=10)
    settings = _settings(total=2, per_racer=1)
    first, second = _lease(sessions, settings), _lease(sessions, settings)
    assert (first.job_id, second.job_id) == (c1, a1)  # priority first, then the oldest
    assert _lease(sessions, settings) is None  # two running: the total is reached
    with sessions() as session:
        assert finish_training(session, first, "done", 60.0)
    third = _lease(sessions, settings)
    assert third.job_id == b1  # alice already runs one: her second waits
    with sessions() as session:
        assert finish_training(session, second, "done", 60.0)
    assert _lease(sessions, settings).job_id == a2


def test_two_trainers_never_hold_one_job(sessions) -> None:
    owners = [_racer(sessions, f"qb_{i}") for i in range(6)]
    for owner in owners:
        _job(sessions, owner)
    settings = _settings(total=4, per_racer=1)
    won: list[int] = []
    barrier = threading.Barrier(8)

    def trainer(index: int) -> None:
        barrier.wait()
        lease = _lease(sessions, settings, f"t{index}")
        if lease is not None:
            won.append(lease.job_id)

    threads = [threading.Thread(target=trainer, args=(i,)) for i in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(won) == 4 and len(set(won)) == 4  # the total, each job once


def test_a_dead_trainers_job_returns_then_fails_with_the_reason(sessions) -> None:
    owner = _racer(sessions, "qc_alice")
    job_id = _job(sessions, owner)
    settings = _settings()
    for attempt in (1, 2):
        lease = _lease(sessions, settings, f"host-{attempt}")
        assert lease.attempt == attempt
        with sessions() as session:
            past = utcnow() - timedelta(seconds=1)
            session.execute(
                update(TrainingJob).where(TrainingJob.id == job_id).values(lease_expires_at=past)
            )
            session.commit()
            assert expire_training_leases(session) == ((1, 0) if attempt == 1 else (0, 1))
        with sessions() as session:  # the old trainer can neither report nor finish
            assert not report(session, lease, [("log", {"line": "late"})])
            assert not finish_training(session, lease, "done", 1.0)
            assert heartbeat_training(session, lease, 30) == (None, False)
    with sessions() as session:
        job = session.get_one(TrainingJob, job_id)
        assert job.status == "failed" and "host-2" in job.error and "2 attempts" in job.error
        assert job.compute_seconds >= 0 and job.finished_at is not None


def test_a_stop_reaches_the_trainer_at_its_heartbeat(sessions) -> None:
    owner = _racer(sessions, "qd_alice")
    job_id = _job(sessions, owner)
    lease = _lease(sessions, _settings())
    with sessions() as session:
        assert heartbeat_training(session, lease, 30)[1] is False
        request_stop(session, session.get_one(TrainingJob, job_id))
        renewed, stop = heartbeat_training(session, lease, 30)
        assert renewed is not None and stop is True
        assert report(
            session, renewed, [("iteration", {"iteration": 0, "eval": {"best_lap": 9.5}})]
        )
        assert session.get_one(TrainingJob, job_id).best_lap_ms == 9500
        kinds = [e.kind for e in session.query(TrainingEvent).filter_by(job_id=job_id)]
        assert kinds == ["status", "log", "iteration"]
