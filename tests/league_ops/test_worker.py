"""Workers in-process: leasing, exactly-once recording, determinism, hostile models."""

from __future__ import annotations

import hashlib
import json
from datetime import timedelta

from sqlalchemy import func, select

from arena.config import RaceConfig
from arena.race import run_race
from league.jobs.evaluation import build_plan, policies
from league.jobs.queue import claim_done, expire_leases, fail_job, heartbeat, lease_job
from league.jobs.worker import Worker
from league.models import Job, Race, RaceCar, utcnow
from tests.league_ops.conftest import Ops
from tests.league_ops.helpers import enter, event, model, racer, statuses
from tests.league_ops.hostile import memory_onnx, nan_onnx, slow_onnx


def drain(worker: Worker) -> None:
    """Run the worker in this process until the queue is empty."""
    while worker.run_once():
        pass


def test_time_trial_jobs_race_and_rerun_identically(ops: Ops) -> None:
    ev = event(ops)
    entry = enter(ops, ev, model(ops, racer(ops, "ada")))
    drain(Worker(ops.settings, "w1"))
    assert statuses(ops) == {"done": 2}
    with ops.sessions() as session:
        races = session.scalars(select(Race).order_by(Race.id)).all()
        assert len(races) == 2 and {r.seed for r in races} == {0, 1}
        for race in races:
            job = session.get_one(Job, race.job_id)
            assert job.entry_id == entry.id and race.ruleset_hash == ev.ruleset_hash
            # determinism: the stored config and the model reproduce the stored result
            config = RaceConfig.model_validate(race.config)
            again = run_race(config, policies(build_plan(session, ops.storage, job)))
            (car,) = race.cars
            (fresh,) = again.cars
            assert car.lap_times_ms == [round(t * 1000) for t in fresh.lap_times]
            assert (car.status, car.distance_m, car.off_track_count) == (
                fresh.status,
                fresh.distance,
                fresh.off_track_count,
            )
            text = json.dumps(again.replay_data(), separators=(",", ":")).encode()
            assert hashlib.sha256(text).hexdigest() == race.trace_sha256


def test_a_result_is_recorded_once_per_job_even_after_lease_expiry(ops: Ops) -> None:
    ev = event(ops, seeds=[0])
    enter(ops, ev, model(ops, racer(ops, "ada")))
    with ops.sessions() as session:
        first = lease_job(session, "slow-worker", 2.0)
        assert first is not None and lease_job(session, "other", 2.0) is None
        # the lease runs out; the job goes back and another worker takes it
        assert expire_leases(session, utcnow() + timedelta(seconds=5)) == (1, 0)
        second = lease_job(session, "fast-worker", 2.0)
        assert second is not None and second.attempt == 2
        assert heartbeat(session, first, 2.0) is None  # the old lease is gone
        assert not claim_done(session, first)
        session.rollback()
        assert claim_done(session, second)
        session.commit()
        assert not claim_done(session, second)  # done already: never twice
        session.rollback()


def test_expired_jobs_fail_after_max_attempts_keeping_the_last_error(ops: Ops) -> None:
    ev = event(ops, seeds=[0])
    enter(ops, ev, model(ops, racer(ops, "ada")))
    with ops.sessions() as session:
        lease = lease_job(session, "w", 2.0)
        assert fail_job(session, lease, "boom: the arena broke", retry=True)
        for _ in range(2):
            lease_job(session, "w", 2.0)
            expire_leases(session, utcnow() + timedelta(seconds=5))
        job = session.scalar(select(Job))
        assert (job.status, job.attempts) == ("failed", 3)
        assert "gave up after 3 attempts" in job.error and "expired" in job.error


def test_hostile_models_fail_or_lose_their_race_with_clear_errors_and_others_finish(
    ops: Ops,
) -> None:
    ev = event(ops, seeds=[0])
    owners = {name: racer(ops, name) for name in ("good", "nan", "hog", "slow")}
    graphs = {"good": None, "nan": nan_onnx(), "hog": memory_onnx(), "slow": slow_onnx()}
    entries = {name: enter(ops, ev, model(ops, owners[name], graphs[name])) for name in owners}
    settings = ops.settings.model_copy(
        update={"race_memory_mb": 512, "race_cpu_seconds": 3, "race_wall_seconds": 30.0}
    )
    drain(Worker(settings, "w1"))
    with ops.sessions() as session:
        jobs = {j.entry_id: j for j in session.scalars(select(Job))}
        errors = {name: jobs[e.id].error for name, e in entries.items()}
        assert jobs[entries["good"].id].status == "done", errors
        # NaN on race observations, or a graph that cannot get its memory under the race's
        # limit, costs the car its race (a DNF with the reason), not the job
        cars = {
            name: session.scalar(select(RaceCar).where(RaceCar.entry_id == entries[name].id))
            for name in ("nan", "hog")
        }
        assert {jobs[entries[name].id].status for name in cars} == {"done"}, errors
        assert cars["nan"].status == "dnf" and "NaN or inf" in cars["nan"].dnf_reason
        assert cars["hog"].status == "dnf"
        assert "Failed to allocate memory" in cars["hog"].dnf_reason
        assert "/onnxruntime_src" not in cars["hog"].dnf_reason  # no build paths shown
        assert jobs[entries["slow"].id].status == "failed", errors
        assert "CPU-time limit of 3 s" in errors["slow"]
        assert session.scalar(select(func.count(RaceCar.id))) == 3


def test_an_idle_worker_finds_nothing(ops: Ops) -> None:
    assert not Worker(ops.settings, "idle").run_once()
