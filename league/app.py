"""``create_app(settings)``: the league's FastAPI application (OpenAPI at ``/docs``)."""

from __future__ import annotations

import logging

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

from league.api import events, health, jobs, models, racers, races, tracks
from league.api.events import LeaderboardCache
from league.bodylimit import BodyLimitMiddleware
from league.db import make_engine, make_session_factory
from league.ratelimit import RateLimitMiddleware
from league.settings import Settings
from league.storage import Storage
from league.web import STATIC_DIR
from league.web import model_data as web_model_data
from league.web import routes as web_routes

log = logging.getLogger("league")
MULTIPART_OVERHEAD = 64 * 1024


def _describe(exc: RequestValidationError) -> str:
    parts = []
    for err in exc.errors()[:5]:
        where = ".".join(str(p) for p in err.get("loc", ()) if p != "body") or "request"
        parts.append(f"{where}: {err.get('msg', 'invalid')}")
    return "Invalid request: " + "; ".join(parts)


def _install_error_handlers(app: FastAPI) -> None:
    @app.exception_handler(StarletteHTTPException)
    async def http_error(_request: Request, exc: StarletteHTTPException) -> JSONResponse:
        return JSONResponse(
            {"detail": str(exc.detail)}, status_code=exc.status_code, headers=exc.headers
        )

    @app.exception_handler(RequestValidationError)
    async def invalid_request(_request: Request, exc: RequestValidationError) -> JSONResponse:
        errors = [
            {"loc": [str(p) for p in e.get("loc", ())], "msg": str(e.get("msg", ""))}
            for e in exc.errors()
        ]
        return JSONResponse({"detail": _describe(exc), "errors": errors}, status_code=422)

    @app.exception_handler(Exception)
    async def server_error(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unhandled error on %s %s", request.method, request.url.path)
        return JSONResponse(
            {"detail": "The server failed on this request; the error was logged."},
            status_code=500,
        )


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the app for ``settings`` (migrations are the caller's job: see ``serve``)."""
    settings = settings or Settings()
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    engine = make_engine(settings.db_url, settings.sqlite_busy_timeout_ms)
    app = FastAPI(
        title="Slipstream league",
        version="1",
        description="Racers upload models, enter events and read leaderboards and races.",
    )
    app.state.settings = settings
    app.state.engine = engine
    app.state.session_factory = make_session_factory(engine)
    app.state.storage = Storage(settings.storage_dir)
    app.state.leaderboards = LeaderboardCache()
    for module in (health, racers, models, events, jobs, races, tracks, web_model_data):
        app.include_router(module.router)
    app.include_router(web_routes.router)
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    _install_error_handlers(app)
    body_cap = settings.max_upload_bytes + MULTIPART_OVERHEAD
    app.add_middleware(BodyLimitMiddleware, max_bytes=body_cap)
    app.add_middleware(
        RateLimitMiddleware, rate=settings.rate_limit_per_second, burst=settings.rate_limit_burst
    )
    return app
