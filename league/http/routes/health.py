"""``/healthz`` (the process answers) and ``/readyz`` (database reachable, schema current,
file store takes a write)."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse
from sqlalchemy.exc import SQLAlchemyError

from league.migrations import is_current

router = APIRouter(tags=["health"])
STORAGE_PROBE_MAX_AGE_S = 1.0
"""How long a file-store write probe's answer is reused (readiness is polled often)."""


@router.get("/healthz")
def healthz() -> dict[str, str]:
    """Liveness: the server is running."""
    return {"status": "ok"}


@router.get(
    "/readyz",
    responses={503: {"description": "Database unreachable or not migrated, or disk not writable"}},
)
def readyz(request: Request) -> JSONResponse:
    """Readiness: the database answers and is at the newest migration, and the file store
    takes a small fsynced write (a full or read-only disk makes the server not ready)."""
    try:
        current = is_current(request.app.state.engine)
    except SQLAlchemyError:
        return JSONResponse({"status": "unavailable", "detail": "database unreachable"}, 503)
    if not current:
        return JSONResponse(
            {"status": "unavailable", "detail": "database migrations are not current"}, 503
        )
    problem = request.app.state.storage.write_problem(STORAGE_PROBE_MAX_AGE_S)
    if problem is not None:
        return JSONResponse({"status": "unavailable", "detail": problem}, 503)
    return JSONResponse({"status": "ok"})
