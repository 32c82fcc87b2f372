"""API tokens: 32 random bytes shown once, stored only as their sha256 (or, once revoked,
as a value no token hashes to).

FastAPI dependencies resolve the bearer token to a :class:`~league.models.Racer`:
``current_racer`` (401 without a valid token), ``optional_racer`` and ``admin_racer``
(401 anonymous, 403 for a racer).
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
from typing import Annotated

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy import select
from sqlalchemy.orm import Session

from league.api.deps import SessionDep
from league.models import Racer

bearer = HTTPBearer(
    auto_error=False, description="The API token from `create-racer` or `rotate-token`."
)


def new_token() -> str:
    """A fresh random API token (URL-safe text)."""
    return secrets.token_urlsafe(32)


def hash_token(token: str) -> str:
    """The stored form of a token: hex sha256."""
    return hashlib.sha256(token.encode("utf-8", "surrogatepass")).hexdigest()


def revoked_hash() -> str:
    """A stored token hash that no token matches, for a revoked token.

    ``hash_token`` only yields hex digits; this value starts with ``revoked:``, so no
    digest ever equals it, and its random part keeps the unique column unique.
    """
    return "revoked:" + secrets.token_urlsafe(32)


def racer_for_token(session: Session, token: str) -> Racer | None:
    """The racer holding ``token``, or None; the final comparison is constant-time."""
    digest = hash_token(token)
    racer = session.scalar(select(Racer).where(Racer.token_hash == digest))
    if racer is None or not hmac.compare_digest(racer.token_hash, digest):
        return None
    return racer


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
