"""``/api/events``: create events (admins), read them, enter models, read leaderboards."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Query, Request, Response
from pydantic import BaseModel
from sqlalchemy import select

from league import crud
from league.head_to_head import HeadToHead, head_to_head
from league.http.auth import AdminRacer, CurrentRacer
from league.http.deps import SessionDep, SettingsDep
from league.http.read_cache import Prepared, answer, event_version, prepared
from league.jobs.faults import fault_count
from league.models import Entry, Event, Model, utcnow
from league.ranking import leaderboard, standing_row
from league.schemas import (
    MAX_ID,
    EntryAccepted,
    EntryCreate,
    ErrorOut,
    EventCreate,
    EventOut,
    Leaderboard,
    LeaderboardRow,
)

router = APIRouter(prefix="/api/events", tags=["events"])
EventId = Annotated[int, Path(ge=1, le=MAX_ID)]
NOT_FOUND = {404: {"model": ErrorOut, "description": "No such event"}}
RETRY_AFTER_SECONDS = 60


class EntryStatus(BaseModel):
    """One of your entries in an event: whether it still races, and if not, why.

    ``fault_dnfs`` counts the event's races it was taken out of for model faults (NaN or
    inf outputs, steps over the CPU budget); at the league's limit the entry is suspended
    and ``suspension`` says why."""

    entry_id: int
    event_id: int
    model_id: int
    created_at: datetime
    fault_dnfs: int
    suspended: bool
    suspended_at: datetime | None
    suspension: str | None


def event_out(event: Event) -> EventOut:
    """The API view of an event, with its status now."""
    return EventOut.model_validate(event, from_attributes=True)


def get_event(session: SessionDep, event_id: int) -> Event:
    """The event or a 404."""
    event = session.get(Event, event_id)
    if event is None:
        raise HTTPException(404, f"Event {event_id} not found.")
    return event


@router.post("", status_code=201, response_model=EventOut, responses={422: {"model": ErrorOut}})
def create_event(body: EventCreate, session: SessionDep, admin: AdminRacer) -> EventOut:
    """Create an event (admins only); its ruleset is frozen from now on."""
    try:
        event = crud.create_event(session, body, admin.id)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    return event_out(event)


@router.get("", response_model=list[EventOut])
def list_events(
    session: SessionDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 100,
    offset: Annotated[int, Query(ge=0, le=MAX_ID)] = 0,
) -> list[EventOut]:
    """League events, newest first (racers' evaluations of their models are unlisted)."""
    query = (
        select(Event)
        .where(Event.kind == "league")
        .order_by(Event.id.desc())
        .limit(limit)
        .offset(offset)
    )
    return [event_out(e) for e in session.scalars(query)]


@router.get("/{event_id}", response_model=EventOut, responses=NOT_FOUND)
def read_event(event_id: EventId, session: SessionDep) -> EventOut:
    """One event with its frozen ruleset."""
    return event_out(get_event(session, event_id))


@router.post(
    "/{event_id}/entries",
    status_code=202,
    response_model=EntryAccepted,
    responses={
        **NOT_FOUND,
        409: {"model": ErrorOut, "description": "Closed, entered, or at the entries cap"},
        429: {"model": ErrorOut, "description": "Too many of your jobs are waiting"},
    },
)
def enter_event(
    event_id: EventId,
    body: EntryCreate,
    racer: CurrentRacer,
    session: SessionDep,
    settings: SettingsDep,
) -> EntryAccepted:
    """Enter one of your models; evaluation jobs are queued (one per seed of the event).

    A racer may have ``max_entries_per_racer`` entries in an event (409 past it) and
    ``max_queued_jobs_per_racer`` evaluation jobs waiting or running (429 with Retry-After
    when the entry's jobs would pass it)."""
    event = get_event(session, event_id)
    model = session.get(Model, body.model_id)
    if model is None or model.owner_id != racer.id:
        raise HTTPException(404, f"Model {body.model_id} is not one of your models.")
    try:
        entry, jobs = crud.enter_model(
            session,
            event,
            model,
            utcnow(),
            max_entries=settings.max_entries_per_racer,
            max_queued=settings.max_queued_jobs_per_racer,
        )
    except crud.QueueFull as exc:
        headers = {"Retry-After": str(RETRY_AFTER_SECONDS)}
        raise HTTPException(429, str(exc), headers=headers) from None
    except crud.Conflict as exc:
        raise HTTPException(409, str(exc)) from None
    return EntryAccepted(
        entry_id=entry.id, event_id=event.id, model_id=model.id, job_ids=[j.id for j in jobs]
    )


@router.get("/{event_id}/entries", response_model=list[EntryStatus], responses=NOT_FOUND)
def read_my_entries(
    event_id: EventId, racer: CurrentRacer, session: SessionDep
) -> list[EntryStatus]:
    """Your entries in the event, oldest first: fault DNFs and whether each is suspended
    (with the reason) after breaking too many of the event's races."""
    event = get_event(session, event_id)
    query = (
        select(Entry)
        .where(Entry.event_id == event.id, Entry.racer_id == racer.id)
        .order_by(Entry.id)
    )
    return [
        EntryStatus(
            entry_id=e.id,
            event_id=e.event_id,
            model_id=e.model_id,
            created_at=e.created_at,
            fault_dnfs=fault_count(session, e.id),
            suspended=e.suspended_at is not None,
            suspended_at=e.suspended_at,
            suspension=e.suspension,
        )
        for e in session.scalars(query)
    ]


@router.get("/{event_id}/head-to-head", response_model=list[HeadToHead], responses=NOT_FOUND)
def read_head_to_head(event_id: EventId, session: SessionDep) -> list[HeadToHead]:
    """Per pairing of models, the races they drove together and who finished ahead."""
    return head_to_head(session, get_event(session, event_id).id)


def _build_leaderboard(request: Request, event_id: int) -> Prepared | None:
    with request.app.state.session_factory() as session:
        event = session.get(Event, event_id)
        if event is None:
            return None
        standings = leaderboard(session, event)
        board = Leaderboard(
            event_id=event.id,
            race_type=event.race_type,
            ranking_metric=event.ranking_metric,
            rows=[LeaderboardRow.model_validate(standing_row(s)) for s in standings],
        )
        return Prepared.of(board.model_dump_json().encode(), "application/json")


@router.get("/{event_id}/leaderboard", response_model=Leaderboard, responses=NOT_FOUND)
async def read_leaderboard(event_id: EventId, request: Request) -> Response:
    """Standings: rank, alias, laps, best / average / total lap time, incidents, racing
    metrics (overtakes, times overtaken, at-fault collisions, laps led, gap to the winner),
    score, submissions; head-to-head events add mu, sigma and the conservative ordinal.

    Built once per results_version of the event (``league.http.read_cache``), answered with an
    ETag; ``If-None-Match`` with the current one answers 304.
    """
    version = event_version(request, event_id)
    if version is None:
        raise HTTPException(404, f"Event {event_id} not found.")
    key = ("leaderboard", event_id, version)
    item = await prepared(request, key, lambda: _build_leaderboard(request, event_id))
    if item is None:
        raise HTTPException(404, f"Event {event_id} not found.")
    return answer(request, item)
