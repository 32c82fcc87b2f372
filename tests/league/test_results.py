"""Recording results: the worker's one transaction, the job's completion, results_version."""

from __future__ import annotations

from sqlalchemy import func, select

from league.jobs.queue import evaluation_jobs, release
from league.jobs.worker import record_result
from league.models import Event, Job, Race
from tests.league.conftest import League
from tests.league.helpers import car, create_event, enter, lease, race_result, record, upload


def results_version(league: League, event_id: int) -> int:
    """The event's stored results_version."""
    with league.sessions() as session:
        return session.get_one(Event, event_id).results_version


def test_a_job_is_done_only_through_its_lease(league: League) -> None:
    event = create_event(league, name="Leases", seeds=[0])
    entry = enter(league, "alice", event["id"], upload(league, "alice", seed=51)["id"])
    (job_id,) = entry["job_ids"]
    with league.sessions() as session:
        result = race_result(session.get_one(Event, event["id"]), [car("a")])
        cars = {"a": entry["entry_id"]}
        stale = lease(session, job_id)
        release(session, stale)  # the job went back to the queue: this lease holds nothing
        assert record_result(session, league.storage, stale, result, cars) is None
        races = select(func.count(Race.id)).where(Race.event_id == event["id"])
        assert session.scalar(races) == 0
        held = lease(session, job_id)
        race = record_result(session, league.storage, held, result, cars)
        assert race is not None and race.job_id == job_id
        job = session.get_one(Job, job_id)
        assert (job.status, job.lease_owner, job.lease_expires_at) == ("done", None, None)
        assert record_result(session, league.storage, held, result, cars) is None  # once only
        assert session.scalar(races) == 1


def test_every_leaderboard_write_bumps_results_version(league: League) -> None:
    event = create_event(league, name="Versions", race_type="head_to_model", round_interval_s=600)
    start = results_version(league, event["id"])
    ea = enter(league, "alice", event["id"], upload(league, "alice", seed=52)["id"])
    eb = enter(league, "bob", event["id"], upload(league, "bob", seed=53)["id"])
    assert results_version(league, event["id"]) == start + 2  # one per entry
    cars = {ea["entry_id"]: car("a"), eb["entry_id"]: car("b", finish_position=2)}
    record(league, event["id"], cars)
    assert results_version(league, event["id"]) == start + 4  # the race, then the ratings


def test_an_entry_queues_one_evaluation_job_per_seed(league: League) -> None:
    event = create_event(league, name="Seeds", seeds=[5, 6])
    entry = enter(league, "bob", event["id"], upload(league, "bob", seed=54)["id"])
    expected = evaluation_jobs(event["id"], entry["entry_id"], [5, 6])
    assert [row["seed"] for row in expected] == [5, 6]
    with league.sessions() as session:
        jobs = session.scalars(select(Job).where(Job.id.in_(entry["job_ids"])).order_by(Job.id))
        stored = [{key: getattr(job, key) for key in expected[0]} for job in jobs]
    assert stored == expected
