"""Who is calling: FastAPI dependencies that resolve the bearer token to a
:class:`~league.models.Racer` (through :func:`league.tokens.racer_for_token`):
``current_racer`` (401 without a valid token), ``optional_racer`` and ``admin_racer``
(401 anonymous, 403 for a racer).
"""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from league.http.deps import SessionDep
from league.models import Racer
from league.tokens import racer_for_token

bearer = HTTPBearer(
    auto_error=False, description="The API token from `create-racer` or `rotate-token`."
)


def invalid_token() -> HTTPException:
    """The 401 for a token that matches nobody (unknown, rotated away or revoked)."""
    return HTTPException(401, "The API token is not valid.", headers={"WWW-Authenticate": "Bearer"})


def optional_racer(
    request: Request,
    session: SessionDep,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
) -> Racer | None:
    """The caller, or None when anonymous; a token that matches nobody is refused (401)."""
    if credentials is None:
        return None
    racer = racer_for_token(session, credentials.credentials)
    if racer is None:
        raise invalid_token()
    request.state.racer_id = racer.id
    return racer


def current_racer(racer: Annotated[Racer | None, Depends(optional_racer)]) -> Racer:
    """The caller; anonymous calls get 401."""
    if racer is None:
        raise HTTPException(
            401,
            "This route needs an API token: send 'Authorization: Bearer <token>'.",
            headers={"WWW-Authenticate": "Bearer"},
        )
    return racer


def admin_racer(racer: Annotated[Racer, Depends(current_racer)]) -> Racer:
    """The caller if they are an admin; racers get 403."""
    if racer.role != "admin":
        raise HTTPException(403, "Only a league admin may do this.")
    return racer


OptionalRacer = Annotated[Racer | None, Depends(optional_racer)]
CurrentRacer = Annotated[Racer, Depends(current_racer)]
AdminRacer = Annotated[Racer, Depends(admin_racer)]
