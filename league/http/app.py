"""``create_app(settings)``: the league's FastAPI application (OpenAPI at ``/docs``)."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import numpy  # noqa: F401  loaded before threadpool_limits, which limits loaded libraries only
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException
from threadpoolctl import threadpool_limits

from league.db import make_engine, make_session_factory
from league.http.bodylimit import BodyLimitMiddleware, BodyRule
from league.http.ratelimit import RateLimitMiddleware
from league.http.read_cache import ReadCache
from league.http.routes import (
    analysis,
    checkpoints,
    evaluations,
    events,
    garage,
    health,
    jobs,
    models,
    racers,
    races,
    tracks,
    training,
)
from league.http.security import SecurityHeadersMiddleware
from league.http.training_feed import TrainingFeed
from league.http.upload_validation import UploadValidator
from league.settings import Settings
from league.store import open_storage
from league.store.base import StorageError
from league.store.sweep import sweep
from league.web import STATIC_DIR
from league.web import docs as web_docs
from league.web import model_data as web_model_data
from league.web import routes as web_routes

log = logging.getLogger("league")
MULTIPART_OVERHEAD = 64 * 1024
TRAINING_JOB_BODY_BYTES = 160 * 1024  # a 64 KiB reward source, JSON-escaped, and options


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

    @app.exception_handler(StorageError)
    async def storage_error(request: Request, exc: StorageError) -> JSONResponse:
        log.error("file store failed on %s %s: %s", request.method, request.url.path, exc)
        detail = (
            "The server's file store is full"
            if exc.full
            else "The server cannot write to its file store right now"
        )
        return JSONResponse(
            {"detail": f"{detail}; nothing was saved. Try again later."},
            status_code=507 if exc.full else 503,
            headers={"Retry-After": "60"},
        )

    @app.exception_handler(Exception)
    async def server_error(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unhandled error on %s %s", request.method, request.url.path)
        return JSONResponse(
            {"detail": "The server failed on this request; the error was logged."},
            status_code=500,
        )


def _install_middleware(app: FastAPI, settings: Settings) -> None:
    """Outermost first: security headers, rate limit, body limits (the last added runs first)."""
    upload = BodyRule(
        settings.max_upload_bytes + MULTIPART_OVERHEAD, settings.upload_timeout_seconds
    )
    training_job = BodyRule(TRAINING_JOB_BODY_BYTES, settings.body_timeout_seconds)
    app.add_middleware(
        BodyLimitMiddleware,
        default=BodyRule(settings.max_body_bytes, settings.body_timeout_seconds),
        routes={
            ("POST", app.url_path_for("upload_model")): upload,
            **{
                ("POST", app.url_path_for(route)): training_job
                for route in ("create_training_job", "check_training_job", "rescore")
            },
        },
    )
    app.add_middleware(
        RateLimitMiddleware, rate=settings.rate_limit_per_second, burst=settings.rate_limit_burst
    )
    app.add_middleware(SecurityHeadersMiddleware)


@asynccontextmanager
async def _lifespan(app: FastAPI) -> AsyncIterator[None]:
    """At start, hold numpy's BLAS to one thread and sweep the file store of crash
    leftovers and unreferenced files.

    The server's BLAS work is small (a racing line for the garage's catalogue is a few
    hundred unknowns) and one thread does it as fast. Threaded, it waits on its own
    threads: on a 2-core host kept busy the catalogue's first build took 50-107 s instead
    of 2-4 (``benchmarks/RESULTS.md``, "A loaded host and the catalogue").
    """
    threadpool_limits(1, user_api="blas")
    state = app.state
    try:
        sweep(state.session_factory, state.storage, state.settings.orphan_grace_seconds)
    except Exception:  # a sweep that fails must not keep the server down
        log.exception("start-up sweep of the file store failed; serving anyway")
    yield


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the app for ``settings`` (migrations are the caller's job: see ``serve``)."""
    settings = settings or Settings()
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    engine = make_engine(settings.db_url, settings.sqlite_busy_timeout_ms)
    app = FastAPI(
        title="Slipstream league",
        version="1",
        description="Racers upload models, enter events and read leaderboards and races.",
        lifespan=_lifespan,
        docs_url=None,  # league.web.docs renders /docs itself: no CDN, no script
        redoc_url=None,
    )
    app.state.settings = settings
    app.state.engine = engine
    app.state.session_factory = make_session_factory(engine)
    app.state.storage = open_storage(settings)
    app.state.read_cache = ReadCache()  # public reads, per results version
    app.state.list_builds = asyncio.Semaphore(1)  # uncached race lists: one at a time
    app.state.upload_validator = UploadValidator(settings)
    # reward checks of new training jobs: sandboxed children, a few at once
    app.state.training_checks = asyncio.Semaphore(settings.validation_concurrency)
    app.state.training_feed = TrainingFeed(app.state.session_factory)  # live events
    api = (health, racers, models, events, jobs, races, tracks, training, evaluations)
    api += (checkpoints, analysis, garage)
    for module in (*api, web_model_data):
        app.include_router(module.router)
    app.include_router(web_routes.router)
    app.include_router(web_docs.router)
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    _install_error_handlers(app)
    _install_middleware(app, settings)
    return app
