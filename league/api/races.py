"""``/api/races``: race results with lap splits and racing metrics, and their replay traces."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Query, Response
from sqlalchemy import select
from sqlalchemy.orm import Session, selectinload

from league.api.deps import SessionDep, StorageDep
from league.models import Entry, Race, Racer
from league.schemas import MAX_ID, ErrorOut, RaceBrief, RaceCarOut, RaceOut

router = APIRouter(prefix="/api/races", tags=["races"])
RaceId = Annotated[int, Path(ge=1, le=MAX_ID)]
NOT_FOUND = {404: {"model": ErrorOut, "description": "No such race"}}


def _aliases(session: Session, races: list[Race]) -> dict[int, str]:
    entry_ids = {c.entry_id for race in races for c in race.cars if c.entry_id is not None}
    if not entry_ids:
        return {}
    rows = session.execute(
        select(Entry.id, Racer.alias)
        .join(Racer, Entry.racer_id == Racer.id)
        .where(Entry.id.in_(entry_ids))
    )
    return dict(rows.all())


def _brief(race: Race, aliases: dict[int, str]) -> dict:
    cars = [
        RaceCarOut.model_validate(c).model_copy(update={"alias": aliases.get(c.entry_id or 0)})
        for c in race.cars
    ]
    return {
        "id": race.id,
        "event_id": race.event_id,
        "seed": race.seed,
        "ruleset_hash": race.ruleset_hash,
        "created_at": race.created_at,
        "has_trace": race.trace_sha256 is not None,
        "cars": cars,
    }


@router.get("", response_model=list[RaceBrief])
def list_races(
    session: SessionDep,
    event: Annotated[int | None, Query(ge=1, le=MAX_ID, description="Only this event")] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0, le=MAX_ID)] = 0,
) -> list[RaceBrief]:
    """Races, newest first, with each car's result."""
    query = select(Race).options(selectinload(Race.cars)).order_by(Race.id.desc())
    if event is not None:
        query = query.where(Race.event_id == event)
    races = list(session.scalars(query.limit(limit).offset(offset)))
    aliases = _aliases(session, races)
    return [RaceBrief.model_validate(_brief(r, aliases)) for r in races]


def _race(session: Session, race_id: int) -> Race:
    race = session.get(Race, race_id, options=[selectinload(Race.cars)])
    if race is None:
        raise HTTPException(404, f"Race {race_id} not found.")
    return race


@router.get("/{race_id}", response_model=RaceOut, responses=NOT_FOUND)
def read_race(race_id: RaceId, session: SessionDep) -> RaceOut:
    """One race: its config, summary and per-car results with lap splits."""
    race = _race(session, race_id)
    brief = _brief(race, _aliases(session, [race]))
    return RaceOut.model_validate({**brief, "config": race.config, "summary": race.summary})


@router.get(
    "/{race_id}/trace",
    responses={
        **NOT_FOUND,
        200: {
            "description": (
                "Replay data: per-car columns per step, bots, obstacles, and the overtake"
                " and contact events"
            ),
            "content": {"application/json": {"schema": {"type": "object"}}},
        },
    },
)
def read_trace(race_id: RaceId, session: SessionDep, storage: StorageDep) -> Response:
    """The race's replay trace (JSON: ``trace``, ``bots``, ``obstacles``, ``events``; races
    stored before racing metrics have no ``events``)."""
    race = _race(session, race_id)
    if race.trace_sha256 is None:
        raise HTTPException(404, f"Race {race_id} has no trace.")
    try:
        data = storage.read("traces", race.trace_sha256)
    except FileNotFoundError:
        raise HTTPException(404, f"The trace file of race {race_id} is missing.") from None
    return Response(content=data, media_type="application/json")
