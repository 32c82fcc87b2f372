"""The HTML pages: home, event leaderboard, race replay, model page, upload form and the garage.

Pages are server-rendered shells; public data is filled in here or fetched by the page's
script from the JSON API. The public pages are rendered once per results version and
answered with an ETag (``league.http.read_cache``); time-dependent parts (countdowns) are
computed in the browser from absolute times, and a page whose events open or close
expires at that moment. Private data (a racer's models) is only fetched by the scripts,
with the token the racer stored in their browser.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Request, Response
from fastapi.responses import HTMLResponse
from fastapi.templating import Jinja2Templates
from jinja2 import pass_context
from markupsafe import Markup
from sqlalchemy.orm import selectinload

from league.head_to_head import head_to_head
from league.http.read_cache import (
    Prepared,
    answer,
    event_version,
    league_version,
    prepared,
    race_version,
)
from league.models import Event, Race, utcnow
from league.schemas import MAX_ID
from league.web import TEMPLATES_DIR
from league.web.queries import event_cards, seconds_left, thumbnail

router = APIRouter(include_in_schema=False)
templates = Jinja2Templates(directory=TEMPLATES_DIR)
templates.env.filters["svg"] = Markup
Id = Annotated[int, Path(ge=1, le=MAX_ID)]


@pass_context
def _url_for(context: dict, name: str, /, **path_params: object) -> str:
    """A path, not an absolute URL: a cached page must not carry one request's Host."""
    return str(context["request"].app.url_path_for(name, **path_params))


templates.env.globals["url_for"] = _url_for


def _page(request: Request, name: str, **context: object) -> HTMLResponse:
    return templates.TemplateResponse(request, name, context)


def _prepared_page(
    request: Request, name: str, expires: datetime | None = None, **context: object
) -> Prepared:
    html = templates.get_template(name).render(request=request, **context)
    return Prepared.of(html.encode(), "text/html; charset=utf-8", _epoch(expires))


def _epoch(moment: datetime | None) -> float | None:
    return None if moment is None else moment.timestamp()


def next_change(events: list[Event], now: datetime) -> datetime | None:
    """The first moment after ``now`` that an event opens or closes (its status changes)."""
    moments = [m for e in events for m in (e.opens_at, e.closes_at) if m is not None and m > now]
    return min(moments, default=None)


def _home(request: Request) -> Prepared:
    with request.app.state.session_factory() as session:
        cards = event_cards(session)
        expires = next_change([c.event for c in cards], utcnow())
        return _prepared_page(request, "home.html", expires, cards=cards)


@router.get("/", response_class=HTMLResponse)
async def home(request: Request) -> Response:
    """Events: open / closed, race type, track thumbnail, racers, time left."""
    key = ("home", league_version(request))
    item = await prepared(request, key, lambda: _home(request))
    assert item is not None
    return answer(request, item)


def _event_page(request: Request, event_id: int) -> Prepared | None:
    with request.app.state.session_factory() as session:
        event = session.get(Event, event_id)
        if event is None:
            return None
        now = utcnow()
        return _prepared_page(
            request,
            "event.html",
            next_change([event], now),
            event=event,
            thumbnail_svg=thumbnail(event.track, event.direction),
            seconds_left=seconds_left(event, now),
            head_to_head=head_to_head(session, event.id),
        )


@router.get("/events/{event_id}", response_class=HTMLResponse)
async def event_page(request: Request, event_id: Id) -> Response:
    """An event's live leaderboard, its head-to-head records and its latest races."""
    version = event_version(request, event_id)
    item = None
    if version is not None:
        key = ("event-page", event_id, version)
        item = await prepared(request, key, lambda: _event_page(request, event_id))
    if item is None:
        raise HTTPException(404, f"Event {event_id} not found.")
    return answer(request, item)


def _race_page(request: Request, race_id: int) -> Prepared | None:
    with request.app.state.session_factory() as session:
        race = session.get(Race, race_id, options=[selectinload(Race.cars)])
        if race is None:
            return None
        event = session.get(Event, race.event_id)
        return _prepared_page(request, "race.html", race=race, event=event)


@router.get("/races/{race_id}", response_class=HTMLResponse)
async def race_page(request: Request, race_id: Id) -> Response:
    """The replay viewer of one race."""
    found = race_version(request, race_id)
    item = None
    if found is not None:
        key = ("race-page", race_id, *found[:2])
        item = await prepared(request, key, lambda: _race_page(request, race_id))
    if item is None:
        raise HTTPException(404, f"Race {race_id} not found.")
    return answer(request, item)


@router.get("/models/{model_id}", response_class=HTMLResponse)
def model_page(request: Request, model_id: Id) -> HTMLResponse:
    """A model: validation report, results history, reward graph (owner's token needed)."""
    return _page(request, "model.html", model_id=model_id)


@router.get("/upload", response_class=HTMLResponse)
def upload_page(request: Request) -> HTMLResponse:
    """Upload a model with your token, and list your models."""
    return _page(request, "upload.html")


@router.get("/garage", response_class=HTMLResponse)
def garage_page(request: Request) -> HTMLResponse:
    """The racer's models and training jobs: create, clone, stop, delete."""
    return _page(request, "garage.html")


@router.get("/garage/new", response_class=HTMLResponse)
def create_model_page(request: Request) -> HTMLResponse:
    """Create a model: track, race type, sensors, action space, reward function, training."""
    return _page(request, "garage_new.html")


@router.get("/garage/jobs/{job_id}", response_class=HTMLResponse)
def training_page(request: Request, job_id: Id) -> HTMLResponse:
    """One training job: the live reward graph and top-down view, evaluate, submit."""
    return _page(request, "training.html", job_id=job_id)


@router.get("/garage/bench", response_class=HTMLResponse)
def bench_page(request: Request) -> HTMLResponse:
    """The analysis bench: re-score a stored trace with a new reward, compare runs."""
    return _page(request, "bench.html")
