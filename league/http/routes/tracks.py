"""``/api/tracks/{name}``: a track's geometry (centre line and borders) for drawing it, and
its thumbnail."""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Literal

import numpy as np
from fastapi import APIRouter, HTTPException, Path, Query, Request, Response
from pydantic import BaseModel

from league.http.read_cache import Prepared, answer, prepared
from league.schemas import ErrorOut
from league.web.queries import thumbnail
from tracks.catalog import NAME_PATTERN, get_track, track_version
from tracks.track import TrackError

router = APIRouter(prefix="/api/tracks", tags=["tracks"])
TrackName = Annotated[str, Path(pattern=NAME_PATTERN.pattern)]
DirectionQuery = Annotated[
    Literal["ccw", "cw"] | None, Query(description="Race direction; default: the file's")
]
Point = tuple[float, float]


class TrackGeometry(BaseModel):
    """A track in one racing direction: points in metres, rounded to the millimetre."""

    name: str
    display_name: str
    direction: Literal["ccw", "cw"]
    is_loop: bool
    length: float
    width: float
    waypoints: list[Point]
    left: list[Point]
    right: list[Point]


def _points(array: np.ndarray) -> list[Point]:
    return [(round(float(x), 3), round(float(y), 3)) for x, y in array]


def _not_found(name: str, error: TrackError) -> HTTPException:
    return HTTPException(404, f"Track {name!r} not found: {error}.")


def _geometry(name: str, direction: Literal["ccw", "cw"] | None) -> Prepared:
    """The track's geometry as JSON, built once per version of the track."""
    try:
        track = get_track(name, direction)
    except TrackError as exc:
        raise _not_found(name, exc) from None
    geometry = TrackGeometry(
        name=track.name,
        display_name=track.display_name,
        direction=track.direction,
        is_loop=track.is_loop,
        length=round(track.length, 4),
        width=round(track.width, 4),
        waypoints=_points(track.waypoints),
        left=_points(track.left),
        right=_points(track.right),
    )
    return Prepared.of(geometry.model_dump_json().encode(), "application/json")


async def _per_version(
    request: Request,
    name: str,
    direction: Literal["ccw", "cw"] | None,
    build: Callable[[str, Literal["ccw", "cw"] | None], Prepared],
) -> Response:
    """``build(name, direction)``'s answer, built once per version of the track's file."""
    try:
        version = track_version(name)
    except TrackError as exc:
        raise _not_found(name, exc) from None
    key = (build.__name__, name, direction, version)
    item = await prepared(request, key, lambda: build(name, direction))
    assert item is not None
    return answer(request, item)


@router.get(
    "/{name}",
    response_model=TrackGeometry,
    responses={404: {"model": ErrorOut, "description": "No such track"}},
)
async def read_track(
    name: TrackName,
    request: Request,
    direction: DirectionQuery = None,
) -> Response:
    """The centre line (waypoints) and left / right borders of a built-in or imported track
    (ETag).

    Built once per version of the track's file (one ``stat`` a request; an imported track
    is read and checked in a worker thread, never on the event loop); the 404's text names
    no server path and lists the built-in tracks only.
    """
    return await _per_version(request, name, direction, _geometry)


def _thumbnail(name: str, direction: Literal["ccw", "cw"] | None) -> Prepared:
    try:
        track = get_track(name, direction)
    except TrackError as exc:
        raise _not_found(name, exc) from None
    svg = thumbnail(track.name, track.direction)
    if svg is None:
        raise HTTPException(404, f"Track {name!r} not found.")
    return Prepared.of(svg.encode(), "image/svg+xml")


@router.get(
    "/{name}/thumbnail.svg",
    response_class=Response,
    responses={
        200: {"content": {"image/svg+xml": {}}, "description": "The thumbnail"},
        404: {"model": ErrorOut, "description": "No such track"},
    },
)
async def read_track_thumbnail(
    name: TrackName,
    request: Request,
    direction: DirectionQuery = None,
) -> Response:
    """The track's small SVG picture, as the event cards show it (ETag)."""
    return await _per_version(request, name, direction, _thumbnail)
