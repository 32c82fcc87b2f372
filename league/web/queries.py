"""Read-only database queries behind the web pages."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from pydantic import BaseModel
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from league.models import Entry, Event, Model, Race, RaceCar, utcnow
from tracks.catalog import get_track
from tracks.plot import track_thumbnail_svg
from tracks.track import TrackError


@dataclass(frozen=True)
class EventCard:
    """What the home page shows of one event."""

    event: Event
    racers: int
    thumbnail_svg: str | None
    seconds_left: float | None


def seconds_left(event: Event, now: datetime) -> float | None:
    """Seconds until the event closes (None: no closing time; 0 once closed)."""
    if event.closes_at is None:
        return None
    return max((event.closes_at - now).total_seconds(), 0.0)


_THUMBNAILS: dict[tuple[str, str], str] = {}


def thumbnail(track: str, direction: str) -> str | None:
    """The track's SVG thumbnail, or None when the track is no longer available.

    Drawn once per (track, direction) and process; a missing track is asked again next time.
    """
    key = (track, direction)
    svg = _THUMBNAILS.get(key)
    if svg is None:
        try:
            svg = track_thumbnail_svg(get_track(track, direction), size=96)  # type: ignore[arg-type]
        except TrackError:
            return None
        _THUMBNAILS[key] = svg
    return svg


def event_cards(session: Session, limit: int = 100) -> list[EventCard]:
    """The newest league events (no evaluations) with their racer counts, thumbnails and
    time left."""
    query = select(Event).where(Event.kind == "league").order_by(Event.id.desc()).limit(limit)
    events = list(session.scalars(query))
    counts = dict(
        session.execute(
            select(Entry.event_id, func.count(func.distinct(Entry.racer_id)))
            .where(Entry.event_id.in_([e.id for e in events]))
            .group_by(Entry.event_id)
        ).all()
    )
    now = utcnow()
    return [
        EventCard(e, counts.get(e.id, 0), thumbnail(e.track, e.direction), seconds_left(e, now))
        for e in events
    ]


class ModelRace(BaseModel):
    """One race a model drove in, as its results history (page and JSON) shows it."""

    race_id: int
    event_id: int
    event_name: str
    car_name: str
    status: str
    laps: int
    lap_times_ms: list[int]
    best_ms: int | None
    total_ms: int | None
    off_track_count: int
    crash_count: int
    finish_position: int
    created_at: datetime


def model_races(session: Session, model: Model, limit: int = 200) -> list[ModelRace]:
    """The model's races, newest first."""
    rows = session.execute(
        select(RaceCar, Race.event_id, Race.created_at, Event.name)
        .join(Race, RaceCar.race_id == Race.id)
        .join(Event, Race.event_id == Event.id)
        .where(RaceCar.model_id == model.id)
        .order_by(Race.id.desc())
        .limit(limit)
    ).all()
    return [
        ModelRace(
            race_id=car.race_id,
            event_id=event_id,
            event_name=event_name,
            car_name=car.car_name,
            status=car.status,
            laps=car.laps,
            lap_times_ms=list(car.lap_times_ms),
            best_ms=car.best_ms,
            total_ms=car.total_ms,
            off_track_count=car.off_track_count,
            crash_count=car.crash_count,
            finish_position=car.finish_position,
            created_at=created_at,
        )
        for car, event_id, created_at, event_name in rows
    ]
