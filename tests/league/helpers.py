"""Builders for league tests: uploads, events and synthetic race results."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from arena.config import RaceConfig
from arena.race import CarResult, RaceResult
from league.jobs.queue import Lease, lease_job, release
from league.jobs.worker import record_result
from league.models import Event, Job, Model
from tests.league.conftest import League, make_model_zip

LEASE_S = 60.0


def upload(league: League, who: str, seed: int, name: str | None = None) -> dict[str, Any]:
    """Upload the archive for ``seed`` as ``who``; the model record."""
    path = make_model_zip(league.models_dir, seed)
    with league.client(who) as client, Path(path).open("rb") as handle:
        data = {"name": name} if name else {}
        response = client.post("/api/models", files={"file": (path.name, handle)}, data=data)
    assert response.status_code in (200, 201), response.text
    return response.json()


def create_event(league: League, **fields: Any) -> dict[str, Any]:
    """Create an event as admin; the event record."""
    body = {"name": "Test Cup", "seeds": [0, 1], **fields}
    with league.client("admin") as client:
        response = client.post("/api/events", json=body)
    assert response.status_code == 201, response.text
    return response.json()


def enter(league: League, who: str, event_id: int, model_id: int) -> dict[str, Any]:
    """Enter a model as ``who``; the 202 answer."""
    with league.client(who) as client:
        response = client.post(f"/api/events/{event_id}/entries", json={"model_id": model_id})
    assert response.status_code == 202, response.text
    return response.json()


def car(
    name: str, status: str = "finished", laps: list[float] | None = None, **kw: Any
) -> CarResult:
    """A synthetic car result; lap times in seconds."""
    laps = [10.0, 9.5, 9.8] if laps is None else laps
    done = status == "finished"
    fields = {
        "name": name,
        "status": status,
        "laps": len(laps),
        "lap_times": laps,
        "best_lap": min(laps) if laps else None,
        "average_lap": sum(laps) / len(laps) if laps else None,
        "total_time": sum(laps) if done else None,
        "off_track_count": 0,
        "crash_count": 0,
        "reset_count": 0,
        "penalty_seconds": 0.0,
        "distance": 20.0 * len(laps),
        "finish_position": 1,
    }
    fields.update(kw)
    return CarResult(**fields)


def race_result(event: Event, cars: list[CarResult], seed: int = 0) -> RaceResult:
    """A synthetic race under ``event``'s ruleset with a small trace."""
    rules = {k: v for k, v in event.ruleset.items() if k not in ("mode",)}
    config = RaceConfig.build(**rules, cars=[{"name": c.name} for c in cars], seed=seed)
    trace = {c.name: {"t": [0.0, 0.066], "x": [0.0, 0.1], "y": [0.0, 0.0]} for c in cars}
    order = [c.name for c in sorted(cars, key=lambda c: c.finish_position)]
    return RaceResult(
        config=config, cars=cars, finish_order=order, duration=30.0, steps=450, trace=trace
    )


def lease(session: Session, job_id: int) -> Lease:
    """Lease job ``job_id`` from the queue as a worker does (older jobs go back untouched)."""
    passed = []
    while (held := lease_job(session, "tests", LEASE_S)) is not None and held.job_id != job_id:
        passed.append(held)
    for other in passed:
        release(session, other)
    assert held is not None, f"job {job_id} is not queued"
    return held


def round_job(session: Session, event_id: int, entry_ids: list[int], seed: int) -> int:
    """Queue a head-to-model round job racing ``entry_ids``, as the scheduler does; its id."""
    last = session.scalar(select(func.max(Job.round)).where(Job.event_id == event_id))
    lineup = [{"entry_id": entry_id} for entry_id in entry_ids]
    job = Job(kind="round", event_id=event_id, round=(last or 0) + 1, seed=seed, lineup=lineup)
    session.add(job)
    session.commit()
    return job.id


def record_as_worker(
    league: League, event_id: int, result: RaceResult, entry_ids: dict[str, int]
) -> int:
    """Store ``result`` the way a worker does, through a leased job; the race id.

    A one-entry race is its entry's evaluation job for the result's seed; a race of several
    entries is a new round job. ``entry_ids`` maps car names to entries.
    """
    with league.sessions() as session:
        if len(entry_ids) == 1:
            (entry_id,) = entry_ids.values()
            seed = result.config.seed
            query = select(Job.id).where(Job.entry_id == entry_id, Job.seed == seed)
            job_id = session.scalar(query)
        else:
            job_id = round_job(session, event_id, list(entry_ids.values()), result.config.seed)
        race = record_result(session, league.storage, lease(session, job_id), result, entry_ids)
        assert race is not None
        return race.id


def record(league: League, event_id: int, cars: dict[int, CarResult], seed: int = 0) -> int:
    """Store a race of the entries ``{entry_id: car}`` through its job (as a worker); its id."""
    with league.sessions() as session:
        event = session.get_one(Event, event_id)
        result = race_result(event, list(cars.values()), seed)
    entry_ids = {car.name: entry_id for entry_id, car in cars.items()}
    return record_as_worker(league, event_id, result, entry_ids)


def model_rows(league: League) -> int:
    """How many model rows exist."""
    with league.sessions() as session:
        return session.scalar(select(func.count(Model.id)))


def start_daemon(
    league: League, module: str, args: list[str], log: Path, **env: str
) -> subprocess.Popen:
    """Run ``python -m module *args`` (a trainer or a worker) against ``league``'s database
    and data directory, polling fast, its output in ``log``; ``env`` adds settings."""
    environment = {
        **os.environ,
        "SLIPSTREAM_DATA_DIR": str(league.settings.data_dir),
        "SLIPSTREAM_DATABASE_URL": league.settings.db_url,
        "SLIPSTREAM_POLL_SECONDS": "0.2",
        **env,
    }
    return subprocess.Popen(
        [sys.executable, "-m", module, *args],
        env=environment,
        stdout=log.open("wb"),
        stderr=subprocess.STDOUT,
    )
