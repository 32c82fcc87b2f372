"""Matchmaking and the scheduler's duties (in-process), and two scheduler daemons at once."""

from __future__ import annotations

import random
import re
import signal
import time
from collections import Counter
from datetime import timedelta

import pytest
from sqlalchemy import select, update

from league.jobs.matchmaking import Candidate, plan_round
from league.jobs.scheduler import Scheduler, round_seeds
from league.jobs.worker import Worker
from league.models import Entry, Event, Job, RaceCar, utcnow
from league.ranking import initial_skill
from tests.league_ops.conftest import Ops
from tests.league_ops.helpers import enter, event, model, racer, statuses, wait_until


def test_every_model_races_k_times_in_grids_of_two_to_max() -> None:
    field = [Candidate(i, 25.0 + i, 8.0) for i in range(9)]
    grids = plan_round(field, k=3, max_cars=4, rng=random.Random(1))
    counts = Counter(slot["entry_id"] for grid in grids for slot in grid)
    assert min(counts.values()) >= 3
    assert all(2 <= len(g) <= 4 and len({str(s) for s in g}) == len(g) for g in grids)


def test_close_ratings_meet_more_often() -> None:
    field = [Candidate(0, 25, 3), Candidate(1, 25.5, 3), Candidate(2, 45, 3)]
    pairs = Counter()
    for seed in range(200):
        (grid, *_) = plan_round(field, k=1, max_cars=2, rng=random.Random(seed))
        pairs[frozenset(s["entry_id"] for s in grid)] += 1
    assert pairs[frozenset({0, 1})] > 3 * pairs[frozenset({0, 2})]


def test_a_lone_model_races_a_bot() -> None:
    (grid,) = plan_round([Candidate(7, 25, 8)], k=1, max_cars=4, rng=random.Random(0))
    assert grid == [{"entry_id": 7}, {"bot": "racer"}]
    (grid,) = plan_round([Candidate(7, 25, 8)], 1, 4, random.Random(0), bot="pursuit")
    assert grid == [{"entry_id": 7}, {"bot": "pursuit"}]


@pytest.mark.parametrize("bot", ["racer", "pursuit"])
def test_a_lone_model_races_the_events_bot_in_that_bots_car(ops: Ops, bot: str) -> None:
    """A head-to-model event's ``round_bot`` fills the grid of its lone model, and races in
    its own car: the racer laps the 23 m speedway at the racing line's pace (about 7.5 s
    from the grid), the pursuit bot at the console's 0.8 m/s does not finish in 20 s."""
    ev = event(ops, race_type="head_to_model", track="slipstream_speedway",
               round_interval_s=60, seeds=[0], round_bot=bot)  # fmt: skip
    enter(ops, ev, model(ops, racer(ops, "ada")))
    races = Scheduler(ops.settings).tick(utcnow())["round_jobs"]
    assert races >= 1
    with ops.sessions() as session:
        lineups = [job.lineup for job in session.scalars(select(Job))]
    assert lineups == [[{"entry_id": 1}, {"bot": bot}]] * races
    worker = Worker(ops.settings, "w")
    while worker.run_once():
        pass
    assert statuses(ops) == {"done": races}
    with ops.sessions() as session:
        cars = session.scalars(select(RaceCar).where(RaceCar.entry_id.is_(None))).all()
    assert len(cars) == races
    for car in cars:
        if bot == "racer":
            assert car.laps == 1 and car.total_ms is not None and car.total_ms < 9000
            assert car.off_track_count == 0 and car.crash_count == 0
        else:
            assert car.laps == 0 and 8.0 < car.distance_m < 18.0  # 0.8 m/s (and noise), 20 s


def test_round_seeds_are_reproducible_fresh_and_unused() -> None:
    first = round_seeds(5, 1, 4, used=[])
    assert first == round_seeds(5, 1, 4, used=[]) and len(set(first)) == 4
    second = round_seeds(5, 2, 4, used=first)
    assert not set(second) & set(first)
    assert round_seeds(6, 1, 4, used=[]) != first  # keyed by event too
    assert not set(round_seeds(5, 1, 4, used=first[:2])) & set(first[:2])


def test_each_round_races_the_same_lineup_on_fresh_seeds(ops: Ops) -> None:
    ev = event(ops, race_type="head_to_model", round_interval_s=60, seeds=[0])
    for alias in ("ada", "bob"):
        enter(ops, ev, model(ops, racer(ops, alias), seed=len(alias) + ord(alias[0])))
    scheduler = Scheduler(ops.settings)
    now = utcnow()
    for number in (1, 2, 3):
        assert scheduler.tick(now + timedelta(seconds=61 * (number - 1)))["round_jobs"] == 2
        with ops.sessions() as session:
            session.execute(update(Job).values(status="done"))  # as if raced
            session.commit()
    with ops.sessions() as session:
        jobs = session.scalars(select(Job).order_by(Job.id)).all()
    used: list[int] = []
    for number in (1, 2, 3):
        rows = [j for j in jobs if j.round == number]
        assert [sorted(s["entry_id"] for s in j.lineup) for j in rows] == [[1, 2], [1, 2]]
        seeds = [j.seed for j in rows]
        assert seeds == round_seeds(ev.id, number, 2, used)  # reproducible, and recorded
        assert not set(seeds) & set(used)  # the lineup never races a seed twice
        used += seeds


def test_rounds_rate_models_and_closing_writes_standings(ops: Ops) -> None:
    ev = event(ops, race_type="head_to_model", round_interval_s=60, seeds=[0])
    for alias in ("ada", "bob", "cyd"):
        enter(ops, ev, model(ops, racer(ops, alias), seed=len(alias) + ord(alias[0])))
    scheduler = Scheduler(ops.settings)
    now = utcnow()
    assert scheduler.tick(now)["round_jobs"] == 2  # 3 models, k = 2, 3 cars a race
    assert scheduler.tick(now)["round_jobs"] == 0  # not due again yet
    worker = Worker(ops.settings, "w")
    while worker.run_once():
        pass
    assert statuses(ops) == {"done": 2}
    with ops.sessions() as session:
        session.execute(update(Event).values(closes_at=now + timedelta(seconds=90)))
        session.commit()
    assert scheduler.tick(now + timedelta(seconds=61))["round_jobs"] == 2
    while worker.run_once():
        pass
    assert scheduler.tick(now + timedelta(seconds=120))["closed"] == 1
    with ops.sessions() as session:
        final = session.get_one(Event, ev.id).final_standings
    assert [row["rank"] for row in final] == [1, 2, 3]
    assert all(row["sigma"] < 25 / 3 and row["ordinal"] is not None for row in final)


def _until_both_ticked(ops: Ops, trial: Event, names: list[str]) -> int:
    """Enter late models into ``trial`` one at a time until every scheduler has queued the
    jobs of one; how many were entered.

    A scheduler logs a tick only when it did something, so a late entry is what makes a
    tick visible: whoever logs ``evaluation_jobs 3`` (this event's 3 seeds; the first
    entries made 18) ticked after all the first jobs existed, over the same rows as the
    other. Which scheduler takes an entry is chance; a few entries are enough.
    """
    picked_up = re.compile(r"tick: evaluation_jobs 3\b")

    def late_ticks() -> list[int]:
        return [len(picked_up.findall(ops.log(name))) for name in names]

    deadline = time.monotonic() + 60
    late = 0
    while not all(late_ticks()):
        assert time.monotonic() < deadline, f"late entries picked up per scheduler: {late_ticks()}"
        late += 1
        md = model(ops, racer(ops, f"late{late}"), seed=100 + late)
        with ops.sessions() as session:
            session.add(Entry(event_id=trial.id, model_id=md.id, racer_id=md.owner_id))
            session.commit()
        wait_until(lambda n=late: sum(late_ticks()) >= n, 30, f"the jobs of late entry {late}")
    return late


def test_two_scheduler_daemons_make_no_duplicate_jobs(ops: Ops) -> None:
    trial = event(ops, seeds=[0, 1, 2])
    h2h = event(ops, race_type="head_to_model", round_interval_s=60, seeds=[0])
    with ops.sessions() as session:  # entries the API queued no jobs for (scheduler's job)
        for i in range(6):
            md = model(ops, racer(ops, f"r{i}"), seed=i)
            session.add(Entry(event_id=trial.id, model_id=md.id, racer_id=md.owner_id))
            session.add(Entry(event_id=h2h.id, model_id=md.id, racer_id=md.owner_id))
        session.commit()
        ids = session.scalars(select(Entry.id).where(Entry.event_id == h2h.id)).all()
    start = initial_skill()
    field = [Candidate(i, start.mu, start.sigma) for i in sorted(ids)]
    expected = plan_round(field, 2, 4, random.Random(f"{h2h.id}:1"))
    # Different periods, so that neither always ticks just before the other.
    polls = {"scheduler0": 0.05, "scheduler1": 0.08}
    names = list(polls)
    procs = [ops.start("scheduler", name, poll_seconds=poll) for name, poll in polls.items()]
    wait_until(lambda: statuses(ops).get("queued", 0) >= 18 + len(expected), 30, "jobs")
    late = _until_both_ticked(ops, trial, names)
    for proc in procs:
        proc.send_signal(signal.SIGTERM)
    assert [proc.wait(timeout=10) for proc in procs] == [0, 0]
    with ops.sessions() as session:
        jobs = session.scalars(select(Job)).all()
    evaluations = Counter((j.entry_id, j.seed) for j in jobs if j.kind == "evaluation")
    assert len(evaluations) == 3 * (6 + late) and set(evaluations.values()) == {1}
    rounds = [j for j in jobs if j.kind == "round"]
    assert {j.round for j in rounds} == {1}  # one round, planned once
    rounds.sort(key=lambda j: j.id)
    assert [j.lineup for j in rounds] == expected
    assert [j.seed for j in rounds] == round_seeds(h2h.id, 1, len(expected), used=[])
    assert "scheduler stopped" in ops.log("scheduler0") + ops.log("scheduler1")
