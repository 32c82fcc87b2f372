"""``/api/models/{id}/evaluations``: race one of your models alone on any track and direction.

An evaluation is an unlisted event (``events.kind = 'evaluation'``) with the model's one
entry: the league's workers race its jobs under the league's rules, as for any entry.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Query
from sqlalchemy import select
from sqlalchemy.orm import Session

from league import crud
from league.http.auth import CurrentRacer
from league.http.deps import SessionDep, SettingsDep
from league.http.routes.events import RETRY_AFTER_SECONDS
from league.models import Entry, Event, Job, Race, RaceCar, utcnow
from league.schemas import (
    MAX_ID,
    ErrorOut,
    EvaluationAccepted,
    EvaluationCreate,
    EvaluationOut,
    EvaluationRace,
    JobOut,
)
from league.web.model_data import owned_model

router = APIRouter(prefix="/api/models", tags=["evaluations"])
ModelId = Annotated[int, Path(ge=1, le=MAX_ID)]
NOT_FOUND = {404: {"model": ErrorOut, "description": "Not one of your models"}}


def evaluation_status(job_statuses: list[str]) -> str:
    """Where an evaluation stands from its jobs' statuses: ``queued`` until one starts,
    ``running`` until all have settled, then ``failed`` if one failed, else ``done``."""
    statuses = set(job_statuses)
    if "running" in statuses or ("queued" in statuses and statuses - {"queued"}):
        return "running"
    if "queued" in statuses or not statuses:
        return "queued"
    return "failed" if "failed" in statuses else "done"


@router.post(
    "/{model_id}/evaluations",
    status_code=201,
    response_model=EvaluationAccepted,
    responses={
        **NOT_FOUND,
        422: {"model": ErrorOut, "description": "Unknown track or direction, bad field"},
        429: {"model": ErrorOut, "description": "Too many of your jobs are waiting"},
    },
)
def create_evaluation(
    model_id: ModelId,
    body: EvaluationCreate,
    racer: CurrentRacer,
    session: SessionDep,
    settings: SettingsDep,
) -> EvaluationAccepted:
    """Evaluate your model alone on a track and direction: an unlisted event under the
    league's default ruleset for the race type, its jobs queued as an entry's are (429
    with Retry-After past ``max_queued_jobs_per_racer`` jobs waiting or running)."""
    model = owned_model(session, racer, model_id)
    if model.owner_id != racer.id:  # admins read others' evaluations, never start them
        raise HTTPException(404, f"Model {model_id} is not one of your models.")
    try:
        event, entry, jobs = crud.create_evaluation(
            session, model, body, utcnow(), max_queued=settings.max_queued_jobs_per_racer
        )
    except crud.QueueFull as exc:
        headers = {"Retry-After": str(RETRY_AFTER_SECONDS)}
        raise HTTPException(429, str(exc), headers=headers) from None
    except ValueError as exc:
        session.rollback()
        raise HTTPException(422, str(exc)) from None
    return EvaluationAccepted(
        event_id=event.id,
        entry_id=entry.id,
        jobs=[JobOut.model_validate(j) for j in jobs],
        track=event.track,
        direction=event.direction,
        race_type=event.race_type,
    )


@router.get("/{model_id}/evaluations", response_model=list[EvaluationOut], responses=NOT_FOUND)
def list_evaluations(
    model_id: ModelId,
    racer: CurrentRacer,
    session: SessionDep,
    limit: Annotated[int, Query(ge=1, le=100)] = 20,
) -> list[EvaluationOut]:
    """Your model's evaluations (admins: any model's), newest first, with their races."""
    model = owned_model(session, racer, model_id)
    return model_evaluations(session, model.id, limit)


def model_evaluations(session: Session, model_id: int, limit: int) -> list[EvaluationOut]:
    """The newest ``limit`` evaluations of a model with their jobs' state and races."""
    rows = session.execute(
        select(Event, Entry.id)
        .join(Entry, Entry.event_id == Event.id)
        .where(Event.kind == "evaluation", Entry.model_id == model_id)
        .order_by(Event.id.desc())
        .limit(limit)
    ).all()
    entry_ids = [entry_id for _, entry_id in rows]
    jobs: dict[int, list[Job]] = {}
    for job in session.scalars(select(Job).where(Job.entry_id.in_(entry_ids)).order_by(Job.id)):
        jobs.setdefault(job.entry_id or 0, []).append(job)
    races: dict[int, list[EvaluationRace]] = {}
    cars = session.scalars(
        select(RaceCar)
        .join(Race, RaceCar.race_id == Race.id)
        .where(RaceCar.entry_id.in_(entry_ids))
        .order_by(Race.seed, Race.id)
    )
    for car in cars:
        races.setdefault(car.entry_id or 0, []).append(
            EvaluationRace(
                race_id=car.race_id,
                status=car.status,
                laps=car.laps,
                lap_times_ms=list(car.lap_times_ms),
                best_lap_ms=car.best_ms,
                total_ms=car.total_ms,
                off_track=car.off_track_count,
                crashes=car.crash_count,
                resets=car.reset_count,
            )
        )
    return [
        EvaluationOut(
            event_id=event.id,
            name=event.name,
            track=event.track,
            direction=event.direction,
            race_type=event.race_type,
            laps=int(event.ruleset.get("laps", 0)),
            created_at=event.created_at,
            status=evaluation_status([j.status for j in jobs.get(entry_id, [])]),
            error=next((j.error for j in jobs.get(entry_id, []) if j.status == "failed"), None),
            races=races.get(entry_id, []),
        )
        for event, entry_id in rows
    ]
