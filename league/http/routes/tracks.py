"""``/api/tracks/{name}``: a track's geometry (centre line and borders) for drawing it."""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from fastapi import APIRouter, HTTPException, Path, Query
from pydantic import BaseModel

from league.schemas import ErrorOut
from tracks.catalog import NAME_PATTERN, get_track
from tracks.track import TrackError

router = APIRouter(prefix="/api/tracks", tags=["tracks"])
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


@router.get(
    "/{name}",
    response_model=TrackGeometry,
    responses={404: {"model": ErrorOut, "description": "No such track"}},
)
def read_track(
    name: Annotated[str, Path(pattern=NAME_PATTERN.pattern)],
    direction: Annotated[
        Literal["ccw", "cw"] | None, Query(description="Race direction; default: the file's")
    ] = None,
) -> TrackGeometry:
    """The centre line (waypoints) and left / right borders of a built-in or imported track.

    An imported track is checked once per version of its file (``tracks.catalog``); the
    404's text names no server path and lists the built-in tracks only.
    """
    try:
        track = get_track(name, direction)
    except TrackError as exc:
        raise HTTPException(404, f"Track {name!r} not found: {exc}.") from None
    return TrackGeometry(
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
