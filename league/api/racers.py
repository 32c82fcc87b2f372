"""``/api/racers``: create racers (admins) and read yourself."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException

from league import crud
from league.api.deps import SessionDep
from league.auth import AdminRacer, CurrentRacer
from league.schemas import ErrorOut, RacerCreate, RacerCreated, RacerOut

router = APIRouter(prefix="/api/racers", tags=["racers"])


@router.post(
    "",
    status_code=201,
    response_model=RacerCreated,
    responses={409: {"model": ErrorOut, "description": "Alias taken"}},
)
def create_racer(body: RacerCreate, session: SessionDep, _admin: AdminRacer) -> RacerCreated:
    """Create a racer (admins only). The answer holds their API token: it is shown once."""
    try:
        racer, token = crud.create_racer(session, body.alias, body.admin)
    except crud.Conflict as exc:
        raise HTTPException(409, str(exc)) from None
    return RacerCreated(**RacerOut.model_validate(racer).model_dump(), token=token)


@router.get("/me", response_model=RacerOut)
def read_me(racer: CurrentRacer) -> RacerOut:
    """The racer the token belongs to."""
    return RacerOut.model_validate(racer)
