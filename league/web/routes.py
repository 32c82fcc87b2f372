"""The HTML pages: home, event leaderboard, race replay, model page and upload form.

Pages are server-rendered shells; public data is filled in here or fetched by the page's
script from the JSON API. Private data (a racer's models) is only fetched by the scripts,
with the token the racer stored in their browser.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Request
from fastapi.responses import HTMLResponse
from fastapi.templating import Jinja2Templates
from markupsafe import Markup
from sqlalchemy.orm import selectinload

from league.api.deps import SessionDep
from league.head_to_head import head_to_head
from league.models import Event, Race, utcnow
from league.schemas import MAX_ID
from league.web import TEMPLATES_DIR
from league.web.queries import event_cards, seconds_left, thumbnail

router = APIRouter(include_in_schema=False)
templates = Jinja2Templates(directory=TEMPLATES_DIR)
templates.env.filters["svg"] = Markup
Id = Annotated[int, Path(ge=1, le=MAX_ID)]


def _page(request: Request, name: str, **context: object) -> HTMLResponse:
    return templates.TemplateResponse(request, name, context)


@router.get("/", response_class=HTMLResponse)
def home(request: Request, session: SessionDep) -> HTMLResponse:
    """Events: open / closed, race type, track thumbnail, racers, time left."""
    return _page(request, "home.html", cards=event_cards(session))


@router.get("/events/{event_id}", response_class=HTMLResponse)
def event_page(request: Request, event_id: Id, session: SessionDep) -> HTMLResponse:
    """An event's live leaderboard, its head-to-head records and its latest races."""
    event = session.get(Event, event_id)
    if event is None:
        raise HTTPException(404, f"Event {event_id} not found.")
    return _page(
        request,
        "event.html",
        event=event,
        thumbnail_svg=thumbnail(event.track, event.direction),
        seconds_left=seconds_left(event, utcnow()),
        head_to_head=head_to_head(session, event.id),
    )


@router.get("/races/{race_id}", response_class=HTMLResponse)
def race_page(request: Request, race_id: Id, session: SessionDep) -> HTMLResponse:
    """The replay viewer of one race."""
    race = session.get(Race, race_id, options=[selectinload(Race.cars)])
    if race is None:
        raise HTTPException(404, f"Race {race_id} not found.")
    event = session.get(Event, race.event_id)
    return _page(request, "race.html", race=race, event=event)


@router.get("/models/{model_id}", response_class=HTMLResponse)
def model_page(request: Request, model_id: Id) -> HTMLResponse:
    """A model: validation report, results history, reward graph (owner's token needed)."""
    return _page(request, "model.html", model_id=model_id)


@router.get("/upload", response_class=HTMLResponse)
def upload_page(request: Request) -> HTMLResponse:
    """Upload a model with your token, and list your models."""
    return _page(request, "upload.html")
