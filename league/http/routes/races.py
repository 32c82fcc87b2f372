"""``/api/races``: race results with lap splits and racing metrics, and their replay traces."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Query, Request, Response
from pydantic import TypeAdapter
from sqlalchemy import select
from sqlalchemy.orm import Session, selectinload

from league.http.read_cache import (
    Prepared,
    answer,
    answer_gzipped,
    event_version,
    gzip_prepared,
    league_version,
    prepared,
    race_version,
)
from league.models import Entry, Event, Race, Racer
from league.schemas import MAX_ID, ErrorOut, RaceBrief, RaceCarOut, RaceOut
from league.store.base import FileStore

router = APIRouter(prefix="/api/races", tags=["races"])
RaceId = Annotated[int, Path(ge=1, le=MAX_ID)]
NOT_FOUND = {404: {"model": ErrorOut, "description": "No such race"}}
RACE_LIST = TypeAdapter(list[RaceBrief])
MAX_LIMIT = 500
MAX_OFFSET = 1000  # deeper pages by keyset (``before``): each offset is a query of its own


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


def _race_list(
    request: Request, event: int | None, before: int | None, limit: int, offset: int
) -> Prepared:
    query = select(Race).options(selectinload(Race.cars)).order_by(Race.id.desc())
    if event is not None:
        query = query.where(Race.event_id == event)
    else:  # racers' evaluations are unlisted: their races are read by event or id
        query = query.join(Event, Race.event_id == Event.id).where(Event.kind == "league")
    if before is not None:
        query = query.where(Race.id < before)
    with request.app.state.session_factory() as session:
        races = list(session.scalars(query.limit(limit).offset(offset)))
        aliases = _aliases(session, races)
        briefs = [RaceBrief.model_validate(_brief(r, aliases)) for r in races]
    return Prepared.of(RACE_LIST.dump_json(briefs), "application/json")


@router.get("", response_model=list[RaceBrief])
async def list_races(
    request: Request,
    event: Annotated[int | None, Query(ge=1, le=MAX_ID, description="Only this event")] = None,
    before: Annotated[
        int | None,
        Query(
            ge=1,
            le=MAX_ID,
            description="Only races with a smaller id: to page on, the "
            "last id of the previous page",
        ),
    ] = None,
    limit: Annotated[int, Query(ge=1, le=MAX_LIMIT)] = 50,
    offset: Annotated[
        int, Query(ge=0, le=MAX_OFFSET, description="Races to skip; further back, use before")
    ] = 0,
) -> Response:
    """League races, newest first, with each car's result (ETag; built once per results
    version); evaluations' races only with ``event``. Page with ``before`` (the last id of
    the previous page): ``offset`` stops at 1000."""
    version: object = league_version(request) if event is None else event_version(request, event)
    key = ("races", event, before, limit, offset, version)
    build = lambda: _race_list(request, event, before, limit, offset)  # noqa: E731
    item = await prepared(request, key, build, request.app.state.list_builds)
    assert item is not None
    return answer(request, item)


def _race(session: Session, race_id: int) -> Race:
    race = session.get(Race, race_id, options=[selectinload(Race.cars)])
    if race is None:
        raise HTTPException(404, f"Race {race_id} not found.")
    return race


def _race_detail(request: Request, race_id: int) -> Prepared:
    with request.app.state.session_factory() as session:
        race = _race(session, race_id)
        brief = _brief(race, _aliases(session, [race]))
        out = RaceOut.model_validate({**brief, "config": race.config, "summary": race.summary})
    return Prepared.of(out.model_dump_json().encode(), "application/json")


def _found(request: Request, race_id: int) -> tuple[int, int, str | None]:
    found = race_version(request, race_id)
    if found is None:
        raise HTTPException(404, f"Race {race_id} not found.")
    return found


@router.get("/{race_id}", response_model=RaceOut, responses=NOT_FOUND)
async def read_race(race_id: RaceId, request: Request) -> Response:
    """One race: its config, summary and per-car results with lap splits (ETag)."""
    event_id, version, _ = _found(request, race_id)
    key = ("race", race_id, event_id, version)
    item = await prepared(request, key, lambda: _race_detail(request, race_id))
    assert item is not None
    return answer(request, item)


def _trace(request: Request, race_id: int, sha256: str) -> Prepared:
    storage: FileStore = request.app.state.storage
    try:
        data = storage.read("traces", sha256)
    except FileNotFoundError:
        raise HTTPException(404, f"The trace file of race {race_id} is missing.") from None
    return gzip_prepared(data, "application/json", f'"{sha256}"')


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
async def read_trace(race_id: RaceId, request: Request) -> Response:
    """The race's replay trace (JSON: ``trace``, ``bots``, ``obstacles``, ``events``; races
    stored before racing metrics have no ``events``). A trace never changes: it is sent
    with ``Cache-Control: immutable`` and gzip-compressed when the client accepts gzip."""
    _, _, sha256 = _found(request, race_id)
    if sha256 is None:
        raise HTTPException(404, f"Race {race_id} has no trace.")
    return await answer_gzipped(
        request, ("trace", sha256), lambda: _trace(request, race_id, sha256)
    )
