"""Builders for league tests: uploads, events and synthetic race results."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from sqlalchemy import func, select

from arena.config import RaceConfig
from arena.race import CarResult, RaceResult
from league import crud
from league.models import Entry, Event, Job, Model
from tests.league.conftest import League, make_model_zip


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


def record(league: League, event_id: int, cars: dict[int, CarResult], seed: int = 0) -> int:
    """Store a race of the entries ``{entry_id: car}`` (marking their job done); its id."""
    with league.sessions() as session:
        event = session.get(Event, event_id)
        entries = {c.name: session.get(Entry, entry_id) for entry_id, c in cars.items()}
        job = None
        if len(cars) == 1:
            (entry_id,) = cars
            job = session.scalar(select(Job).where(Job.entry_id == entry_id, Job.seed == seed))
        result = race_result(event, list(cars.values()), seed)
        race = crud.record_race(session, league.storage, event, result, entries, job)
        if event.race_type == "head_to_model":
            crud.rate_race(session, race)
        return race.id


def model_rows(league: League) -> int:
    """How many model rows exist."""
    with league.sessions() as session:
        return session.scalar(select(func.count(Model.id)))
