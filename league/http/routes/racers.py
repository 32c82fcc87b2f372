"""``/api/racers``: create racers (admins), read yourself, rotate your own API token."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException, Response

from league import crud
from league.http.auth import AdminRacer, CurrentRacer, invalid_token
from league.http.deps import SessionDep
from league.schemas import ErrorOut, RacerCreate, RacerCreated, RacerOut

router = APIRouter(prefix="/api/racers", tags=["racers"])
NO_STORE = {"Cache-Control": "no-store"}


@router.post(
    "",
    status_code=201,
    response_model=RacerCreated,
    responses={409: {"model": ErrorOut, "description": "Alias taken"}},
)
def create_racer(
    body: RacerCreate, session: SessionDep, _admin: AdminRacer, response: Response
) -> RacerCreated:
    """Create a racer (admins only). The answer holds their API token: it is shown once."""
    try:
        racer, token = crud.create_racer(session, body.alias, body.admin)
    except crud.Conflict as exc:
        raise HTTPException(409, str(exc)) from None
    response.headers.update(NO_STORE)
    return RacerCreated(**RacerOut.model_validate(racer).model_dump(), token=token)


@router.get("/me", response_model=RacerOut)
def read_me(racer: CurrentRacer) -> RacerOut:
    """The racer the token belongs to."""
    return RacerOut.model_validate(racer)


@router.post(
    "/me/token",
    response_model=RacerCreated,
    responses={401: {"model": ErrorOut, "description": "No valid token"}},
)
def rotate_my_token(racer: CurrentRacer, session: SessionDep, response: Response) -> RacerCreated:
    """Replace your API token: the answer holds the new one (shown once) and the token that
    made this call stops working at once."""
    me = RacerOut.model_validate(racer).model_dump()
    token = crud.rotate_token(session, racer)
    if token is None:
        raise invalid_token()
    response.headers.update(NO_STORE)
    return RacerCreated(**me, token=token)
