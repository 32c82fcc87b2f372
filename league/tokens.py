"""API tokens: 32 random bytes shown once, stored only as their sha256 (or, once revoked,
as a value no token hashes to).

Plain functions with no web framework, so the worker and the scheduler (which reach them
through :mod:`league.crud`) never import FastAPI; the bearer-token dependency that calls
:func:`racer_for_token` is :mod:`league.http.auth`.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets

from sqlalchemy import select
from sqlalchemy.orm import Session

from league.models import Racer


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
