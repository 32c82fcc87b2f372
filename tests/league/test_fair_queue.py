"""A fair queue: racers (and each event's rounds) are served in turn, per-racer caps on
entries and queued jobs, leases still exactly once, validation slots shared per racer."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Iterator

import pytest
from sqlalchemy import select, update

from league.http.upload_validation import UploadValidator, ValidationBusy
from league.jobs.queue import lease_job
from league.models import Entry, Job
from league.settings import Settings
from tests.league.conftest import League, start_league
from tests.league.helpers import create_event, enter, round_job, upload

MAX_ENTRIES, MAX_QUEUED = 3, 12


@pytest.fixture(scope="module")
def capped(database, tmp_path_factory: pytest.TempPathFactory) -> Iterator[League]:
    """A league with small per-racer caps on entries and queued jobs."""
    folder = tmp_path_factory.mktemp("fair") / "data"
    yield from start_league(
        database, folder, max_entries_per_racer=MAX_ENTRIES, max_queued_jobs_per_racer=MAX_QUEUED
    )


@pytest.fixture
def league(capped: League) -> Iterator[League]:
    """The capped league with an empty queue before and after each test."""
    _settle(capped)
    yield capped
    _settle(capped)


def _settle(league: League) -> None:
    with league.sessions() as session:
        session.execute(update(Job).values(status="done", lease_owner=None))
        session.commit()


def _entered(league: League, who: str, event_id: int, seed: int) -> dict:
    return enter(league, who, event_id, upload(league, who, seed=seed)["id"])


def _owners(league: League, job_ids: list[int]) -> list[str]:
    """Who each job races for: a racer's alias, or ``round`` for a head-to-model job."""
    alias = {v: k for k, v in league.ids.items()}
    with league.sessions() as session:
        racer = dict(session.execute(select(Job.id, Entry.racer_id).outerjoin(Entry)).all())
    return [alias[racer[j]] if racer.get(j) else "round" for j in job_ids]


def _lease_all(league: League) -> list[int]:
    leased = []
    with league.sessions() as session:
        while (lease := lease_job(session, "fair", 60.0)) is not None:
            leased.append(lease.job_id)
    return leased


def test_racers_are_served_in_turn_not_by_job_id(league: League) -> None:
    flood = create_event(league, name="Flood", seeds=list(range(4)))
    for seed in range(3):  # alice: 12 jobs, all queued before bob's two
        _entered(league, "alice", flood["id"], 100 + seed)
    other = create_event(league, name="Other", seeds=[0, 1])
    _entered(league, "bob", other["id"], 200)
    order = _owners(league, _lease_all(league))
    assert len(order) == 14
    assert order[:4] == ["alice", "bob", "alice", "bob"]  # by id: bob would be 13th and 14th


def test_rounds_are_not_starved_by_an_evaluation_flood(league: League) -> None:
    flood = create_event(league, name="Flood 2", seeds=list(range(4)))
    for seed in range(3):
        _entered(league, "alice", flood["id"], 110 + seed)
    h2m = create_event(league, name="Duels", race_type="head_to_model", round_interval_s=600)
    a = _entered(league, "alice", h2m["id"], 120)["entry_id"]
    b = _entered(league, "bob", h2m["id"], 121)["entry_id"]
    with league.sessions() as session:
        rounds = [round_job(session, h2m["id"], [a, b], seed) for seed in (7, 8)]
    leased = _lease_all(league)
    assert len(leased) == 14
    assert set(leased[:4]) >= set(rounds)  # by id they would come last


def test_per_racer_caps_on_entries_and_queued_jobs_give_clear_errors(league: League) -> None:
    many = create_event(league, name="Caps", seeds=list(range(5)))
    few = create_event(league, name="Caps 2", seeds=[0, 1])
    _entered(league, "bob", many["id"], 300)  # 5 jobs queued
    _entered(league, "bob", many["id"], 301)  # 10
    model = upload(league, "bob", seed=302)["id"]
    with league.client("bob") as client:
        full = client.post(f"/api/events/{many['id']}/entries", json={"model_id": model})
        assert full.status_code == 429, full.text
        assert full.headers["Retry-After"] == "60"
        assert full.json()["detail"] == (
            "You have 10 evaluation jobs waiting or running and this entry adds 5; one racer "
            f"may have {MAX_QUEUED}. Enter again once some have raced."
        )
        small = client.post(f"/api/events/{few['id']}/entries", json={"model_id": model})
        assert small.status_code == 202, small.text  # 12 jobs: at the cap, not past it
    _settle(league)  # the jobs ran: the queue cap has room again
    _entered(league, "bob", many["id"], 303)  # bob's third entry in the event
    with league.client("bob") as client:
        last = upload(league, "bob", seed=304)["id"]
        over = client.post(f"/api/events/{many['id']}/entries", json={"model_id": last})
    assert over.status_code == 409, over.text
    assert over.json()["detail"] == (
        f"You have {MAX_ENTRIES} entries in event {many['id']}, the most one racer may have "
        f"({MAX_ENTRIES})."
    )
    with league.sessions() as session:
        assert session.scalar(select(Entry.id).where(Entry.model_id == last)) is None


def test_concurrent_workers_lease_each_job_exactly_once(league: League) -> None:
    event = create_event(league, name="Race for leases", seeds=list(range(4)))
    for who, seed in (("alice", 400), ("alice", 401), ("bob", 402)):
        _entered(league, who, event["id"], seed)
    leased: list[int] = []
    guard = threading.Lock()

    def work() -> None:
        with league.sessions() as session:
            while (lease := lease_job(session, threading.current_thread().name, 60.0)) is not None:
                with guard:
                    leased.append(lease.job_id)

    threads = [threading.Thread(target=work, name=f"w{i}") for i in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=120)
    assert sorted(leased) == sorted(set(leased)) and len(leased) == 12
    with league.sessions() as session:
        counts = session.scalars(select(Job.attempts).where(Job.id.in_(leased))).all()
    assert set(counts) == {1}


def test_one_racers_burst_of_uploads_leaves_a_slot_for_another_racer(tmp_path) -> None:
    settings = Settings(data_dir=tmp_path, validation_concurrency=2, validation_queue=8)

    async def scenario() -> tuple[int, int, bool]:
        validator = UploadValidator(settings)
        release = asyncio.Event()
        holding = 0

        async def upload_as(racer: int) -> None:
            nonlocal holding
            async with validator.slot(racer):
                holding += 1
                await release.wait()

        burst = [asyncio.create_task(upload_as(1)) for _ in range(12)]
        for _ in range(50):  # let every task of the burst run to where it waits or ends
            await asyncio.sleep(0)
        refused = sum(1 for t in burst if t.done() and isinstance(t.exception(), ValidationBusy))
        held_by_one = holding
        async with asyncio.timeout(5):  # the other racer's single upload gets a slot now
            async with validator.slot(2):
                served = True
        release.set()
        await asyncio.gather(*burst, return_exceptions=True)
        return refused, held_by_one, served

    refused, held_by_one, served = asyncio.run(scenario())
    assert served
    assert held_by_one == 1  # all but one of the two slots
    assert refused == 10  # two of the burst in line or validating; the rest told at once
