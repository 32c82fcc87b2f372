"""``/api/training-jobs``: racers train models on the league's trainers.

Creating a job checks its settings here, the admin's quotas, then its reward function in
a sandboxed child (:mod:`league.training.spec`); trainers
(``slipstream league trainer``) run it. Racers see and stop their own jobs; admins see,
stop and re-prioritise everyone's. Progress is readable as lists (``/metrics``, ``/logs``)
and live as Server-Sent Events (``/events``).
"""

from __future__ import annotations

import asyncio
import json
from typing import Annotated

from fastapi import APIRouter, Header, HTTPException, Path, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response, StreamingResponse
from sqlalchemy import delete, select
from sqlalchemy.orm import Session

from agents.recipes import get_recipe
from league.http.auth import AdminRacer, CurrentRacer
from league.http.deps import SessionDep, SettingsDep, StorageDep
from league.http.training_feed import TrainingFeed
from league.models import Racer, TrainingEvent, TrainingJob, utcnow
from league.schemas import (
    MAX_ID,
    ErrorOut,
    TrainingJobCreate,
    TrainingJobOut,
    TrainingJobUpdate,
    TrainingQuota,
)
from league.settings import Settings
from league.training.launch import training_refused
from league.training.queue import (
    QuotaExceeded,
    check_quotas,
    minutes_used,
    next_month,
    request_stop,
)
from league.training.sandbox import SandboxUnavailable
from league.training.spec import (
    JobRefused,
    check_reward,
    check_settings,
    job_fields,
    trains_on,
)

router = APIRouter(prefix="/api/training-jobs", tags=["training"])
JobId = Annotated[int, Path(ge=1, le=MAX_ID)]
MAX_EVENTS = 1000


def job_out(job: TrainingJob) -> TrainingJobOut:
    """The API view of a training job."""
    spec = job.spec
    return TrainingJobOut(
        id=job.id,
        owner=job.owner.alias,
        name=job.name,
        description=spec.get("description"),
        status=job.status,
        priority=job.priority,
        options=spec.get("options", {}),
        recipe=spec.get("recipe"),
        hyperparameters=spec.get("hyperparameters"),
        reward_source=job.reward_source,
        **trains_on(spec),
        minutes=job.minutes,
        clone_of=None if spec.get("resume") else job.clone_of_id,
        resume_of=job.clone_of_id if spec.get("resume") else None,
        attempts=job.attempts,
        error=job.error,
        stop_requested=job.stop_requested_at is not None,
        compute_minutes=round(job.compute_seconds / 60.0, 3),
        best_lap_ms=job.best_lap_ms,
        model_id=job.model_id,
        has_run=job.run_sha256 is not None,
        created_at=job.created_at,
        started_at=job.started_at,
        finished_at=job.finished_at,
    )


def visible_job(session: Session, racer: Racer, job_id: int) -> TrainingJob:
    """The caller's job (admins: anyone's), else 404."""
    job = session.get(TrainingJob, job_id)
    if job is None or (racer.role != "admin" and job.owner_id != racer.id):
        raise HTTPException(404, f"Training job {job_id} not found among your jobs.")
    return job


def _checks(request: Request) -> asyncio.Semaphore:
    return request.app.state.training_checks


async def _checked(
    body: TrainingJobCreate,
    request: Request,
    racer: Racer,
    session: Session,
    settings: Settings,
    quotas: bool,
) -> dict:
    """The job's stored fields once its settings, (with ``quotas``) the quotas and its
    reward function (in a sandboxed child, as ``slipstream train`` checks it) pass; else
    the HTTP error."""
    refused = await run_in_threadpool(training_refused, settings)  # probes once: ~0.1 s
    if refused:
        raise HTTPException(503, refused)
    fields = job_fields(body.options, body.recipe, body.hyperparameters, body.minutes)
    parent = _parent(session, racer, body)
    if body.resume_of is not None:  # the run's own settings: checked as they were stored
        stored = parent.spec
        fields = job_fields(stored["options"], stored["recipe"], None, body.minutes)
        fields["resume"] = True
    try:
        check_settings(fields, cloned=body.clone_of is not None or body.resume_of is not None)
        if quotas:
            _quotas(session, settings, racer.id, body.minutes)
        async with _checks(request):
            source = _reward_source(body, parent)
            await run_in_threadpool(check_reward, settings, fields, source)
    except JobRefused as exc:
        raise HTTPException(422, str(exc)) from None
    except SandboxUnavailable as exc:
        raise HTTPException(503, str(exc)) from None
    return fields


def _parent(session: Session, racer: Racer, body: TrainingJobCreate) -> TrainingJob | None:
    """The job whose stored run ``body`` clones or resumes (one of the caller's), if any;
    422 for a job without a run, or a request that both clones and resumes, or resumes with
    settings of its own."""
    if body.clone_of is not None and body.resume_of is not None:
        raise HTTPException(422, "Give clone_of or resume_of, not both.")
    if body.resume_of is not None and (body.options or body.recipe or body.hyperparameters):
        raise HTTPException(
            422, "resume_of: a resumed run keeps its settings; give no options, recipe or "
            "hyperparameters (clone_of starts a new run from it instead)."
        )  # fmt: skip
    parent_id = body.clone_of or body.resume_of
    if parent_id is None:
        return None
    field = "clone_of" if body.clone_of else "resume_of"
    parent = visible_job(session, racer, parent_id)
    if parent.run_sha256 is None:
        raise HTTPException(422, f"{field}: training job {parent.id} has no stored run.")
    recipe = parent.spec.get("recipe")
    if body.resume_of is not None and recipe and get_recipe(recipe).parent is not None:
        raise HTTPException(
            422, f"resume_of: job {parent.id} races against its parent's model; clone it."
        )
    return parent


def _reward_source(body: TrainingJobCreate, parent: TrainingJob | None) -> str:
    """The reward to train with: the body's, else (resuming) the parent job's."""
    if body.reward_source is not None:
        return body.reward_source
    if body.resume_of is not None and parent is not None:
        return parent.reward_source
    raise HTTPException(422, "reward_source: a new run needs its reward function's source.")


REFUSALS = {
    422: {"model": ErrorOut, "description": "Bad settings, or the reward function fails"},
    503: {"model": ErrorOut, "description": "This server cannot sandbox training"},
}


@router.post(
    "",
    status_code=201,
    response_model=TrainingJobOut,
    responses={
        **REFUSALS,
        404: {"model": ErrorOut, "description": "clone_of is not one of your jobs"},
        429: {"model": ErrorOut, "description": "Over a training quota"},
    },
)
async def create_training_job(
    body: TrainingJobCreate,
    request: Request,
    racer: CurrentRacer,
    session: SessionDep,
    settings: SettingsDep,
) -> TrainingJobOut:
    """Queue a training job. Its settings are checked first, then the quotas, then its
    reward function in a sandboxed child, as ``slipstream train`` checks it."""
    fields = await _checked(body, request, racer, session, settings, quotas=True)
    _quotas(session, settings, racer.id, body.minutes)  # the check took a while
    parent = _parent(session, racer, body)
    job = TrainingJob(
        owner_id=racer.id,
        name=body.name,
        spec={**fields, "description": body.description} if body.description else fields,
        reward_source=_reward_source(body, parent),
        minutes=body.minutes,
        clone_of_id=parent.id if parent is not None else None,
    )
    session.add(job)
    session.commit()
    return job_out(job)


@router.post("/check", responses=REFUSALS)
async def check_training_job(
    body: TrainingJobCreate,
    request: Request,
    racer: CurrentRacer,
    session: SessionDep,
    settings: SettingsDep,
) -> dict[str, bool]:
    """Validate a job without queuing it (DeepRacer's Validate button): its settings and
    its reward function, sandboxed; ``{"ok": true}``, or 422 naming the line."""
    await _checked(body, request, racer, session, settings, quotas=False)
    return {"ok": True}


def _quotas(session: Session, settings: Settings, racer_id: int, minutes: float) -> None:
    try:
        check_quotas(session, settings, racer_id, minutes)
    except QuotaExceeded as exc:
        status = 422 if exc.retry_after is None else 429
        headers = {"Retry-After": str(exc.retry_after)} if exc.retry_after else None
        raise HTTPException(status, str(exc), headers=headers) from None


@router.get("", response_model=list[TrainingJobOut])
def list_training_jobs(
    racer: CurrentRacer,
    session: SessionDep,
    status: Annotated[str | None, Query(max_length=16)] = None,
) -> list[TrainingJobOut]:
    """Your training jobs (admins: everyone's), newest first; ``status`` filters."""
    query = select(TrainingJob).order_by(TrainingJob.id.desc()).limit(500)
    if racer.role != "admin":
        query = query.where(TrainingJob.owner_id == racer.id)
    if status is not None:
        query = query.where(TrainingJob.status == status)
    return [job_out(job) for job in session.scalars(query)]


@router.get("/quota", response_model=TrainingQuota)
def read_quota(racer: CurrentRacer, session: SessionDep, settings: SettingsDep) -> TrainingQuota:
    """Your training minutes this month and when they reset."""
    now = utcnow()
    return TrainingQuota(
        max_minutes_per_job=settings.training_max_minutes,
        jobs_queued_or_running=settings.training_queued_per_racer,
        minutes_per_month=settings.training_minutes_per_month,
        minutes_used=round(minutes_used(session, racer.id, now), 3),
        resets_at=next_month(now),
    )


@router.get("/{job_id}", response_model=TrainingJobOut, responses={404: {"model": ErrorOut}})
def read_training_job(job_id: JobId, racer: CurrentRacer, session: SessionDep) -> TrainingJobOut:
    """One of your training jobs."""
    return job_out(visible_job(session, racer, job_id))


@router.post("/{job_id}/stop", response_model=TrainingJobOut, responses={404: {"model": ErrorOut}})
def stop_training_job(job_id: JobId, racer: CurrentRacer, session: SessionDep) -> TrainingJobOut:
    """Stop a job: a queued one at once; a running one within a heartbeat, keeping the
    model trained so far."""
    job = visible_job(session, racer, job_id)
    request_stop(session, job)
    return job_out(job)


@router.delete(
    "/{job_id}", status_code=204, responses={404: {"model": ErrorOut}, 409: {"model": ErrorOut}}
)
def delete_training_job(job_id: JobId, racer: CurrentRacer, session: SessionDep) -> Response:
    """Delete an ended job and its progress; its model stays one of your models, and its
    stored run is swept with the other files no row refers to. 409 while it is queued or
    running (stop it first)."""
    job = visible_job(session, racer, job_id)
    if job.status in ("queued", "running"):
        raise HTTPException(409, f"Training job {job_id} is {job.status}; stop it first.")
    session.execute(delete(TrainingEvent).where(TrainingEvent.job_id == job.id))
    session.delete(job)
    session.commit()
    return Response(status_code=204)


@router.patch("/{job_id}", response_model=TrainingJobOut, responses={404: {"model": ErrorOut}})
def update_training_job(
    job_id: JobId, body: TrainingJobUpdate, admin: AdminRacer, session: SessionDep
) -> TrainingJobOut:
    """Re-prioritise a job (admins): among waiting jobs the highest priority starts first."""
    job = visible_job(session, admin, job_id)
    job.priority = body.priority
    session.commit()
    return job_out(job)


def _events(session: Session, job_id: int, kind: str, after: int, limit: int) -> list:
    query = (
        select(TrainingEvent)
        .where(TrainingEvent.job_id == job_id, TrainingEvent.id > after)
        .order_by(TrainingEvent.id)
        .limit(limit)
    )
    if kind:
        query = query.where(TrainingEvent.kind == kind)
    return list(session.scalars(query))


@router.get("/{job_id}/metrics", responses={404: {"model": ErrorOut}})
def read_training_metrics(
    job_id: JobId,
    racer: CurrentRacer,
    session: SessionDep,
    after: Annotated[int, Query(ge=0, le=MAX_ID)] = 0,
) -> list[dict]:
    """The job's iterations (the reward graph's series, evaluations included) after the
    event id ``after``; each carries its event ``id``."""
    visible_job(session, racer, job_id)
    rows = _events(session, job_id, "iteration", after, MAX_EVENTS)
    return [{"id": row.id, **row.data} for row in rows]


@router.get("/{job_id}/logs", responses={404: {"model": ErrorOut}})
def read_training_logs(
    job_id: JobId,
    racer: CurrentRacer,
    session: SessionDep,
    after: Annotated[int, Query(ge=0, le=MAX_ID)] = 0,
) -> Response:
    """The job's log as text: its training program's output and status changes (of the
    next 1000 events after ``after``; ``X-Last-Event-Id`` is the ``after`` of the next)."""
    visible_job(session, racer, job_id)
    lines = []
    rows = _events(session, job_id, "", after, MAX_EVENTS)
    for row in rows:
        if row.kind == "log":
            lines.append(str(row.data.get("line", "")))
        elif row.kind == "status":
            error = row.data.get("error")
            lines.append(f"[{row.data.get('status')}]" + (f" {error}" if error else ""))
    last = str(rows[-1].id if rows else after)
    text = "\n".join(lines) + ("\n" if lines else "")
    return Response(text, media_type="text/plain", headers={"X-Last-Event-Id": last})


@router.get("/{job_id}/run.zip", responses={404: {"model": ErrorOut}})
def download_run(
    job_id: JobId, racer: CurrentRacer, session: SessionDep, storage: StorageDep
) -> Response:
    """The run folder (deepracer-for-cloud layout) as a zip."""
    job = visible_job(session, racer, job_id)
    if job.run_sha256 is None:
        raise HTTPException(404, f"Training job {job_id} has no stored run yet.")
    data = storage.read("runs", job.run_sha256)
    name = f"training-job-{job.id}.zip"
    headers = {"Content-Disposition": f'attachment; filename="{name}"'}
    return Response(data, media_type="application/zip", headers=headers)


@router.get("/{job_id}/events", responses={404: {"model": ErrorOut}})
async def stream_training_events(
    job_id: JobId,
    request: Request,
    racer: CurrentRacer,
    session: SessionDep,
    last_event_id: Annotated[int, Header(ge=0, le=MAX_ID)] = 0,
) -> StreamingResponse:
    """The job's events live, as Server-Sent Events (``event:`` iteration, poses, log or
    status; ``id:`` resumes with ``Last-Event-ID``); the stream ends once the job ended."""
    visible_job(session, racer, job_id)
    session.close()
    feed = request.app.state.training_feed
    return StreamingResponse(
        _sse(feed, job_id, last_event_id, request),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"},
    )


async def _sse(feed: TrainingFeed, job_id: int, after: int, request: Request):
    """The job's events as Server-Sent Events, from the process's shared feed."""
    async for event in feed.follow(job_id, after):
        if await request.is_disconnected():
            return
        if event is None:
            yield b": waiting\n\n"
            continue
        data = json.dumps(event.data, separators=(",", ":"), default=str)
        yield f"id: {event.id}\nevent: {event.kind}\ndata: {data}\n\n".encode()
