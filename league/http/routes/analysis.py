"""``/api/rescore``: re-score a logged run (a race's car, a training job's episode) with an
edited reward function, run in a sandboxed child (:mod:`league.training.rescore`)."""

from __future__ import annotations

import io
import json
import zipfile

from fastapi import APIRouter, HTTPException, Request
from fastapi.concurrency import run_in_threadpool
from sqlalchemy.orm import Session

from league.http.auth import CurrentRacer
from league.http.deps import SessionDep, SettingsDep, StorageDep
from league.models import Model, Race, RaceCar, Racer, TrainingJob
from league.schemas import ErrorOut, RescoreCreate, RescoreOut
from league.store.base import FileStore
from league.training.launch import training_refused
from league.training.rescore import (
    Log,
    RescoreRefused,
    answer,
    check_track,
    race_log,
    run_log,
    score_in_sandbox,
)
from league.training.sandbox import SandboxUnavailable
from league.training.spec import trains_on
from submissions.format import REWARD_MEMBER, Limits

router = APIRouter(prefix="/api", tags=["analysis"])
ERRORS = {
    404: {"model": ErrorOut, "description": "No such race, car or training job of yours"},
    409: {"model": ErrorOut, "description": "The training job has no stored run yet"},
    422: {"model": ErrorOut, "description": "The run cannot be re-scored, or the reward failed"},
    503: {"model": ErrorOut, "description": "This server cannot sandbox reward functions"},
}


def model_reward_source(storage: FileStore, model: Model | None) -> str | None:
    """The reward function a model's archive includes (bounded as the validator bounds it),
    else None. The archive is read as a zip only: nothing in it is imported."""
    if model is None:
        return None
    try:
        with zipfile.ZipFile(io.BytesIO(storage.read("models", model.sha256))) as archive:
            info = archive.getinfo(REWARD_MEMBER)
            if info.file_size > Limits().max_reward_function_bytes:
                return None
            return archive.read(info).decode("utf-8")
    except (FileNotFoundError, KeyError, zipfile.BadZipFile, UnicodeDecodeError):
        return None


def _race(session: Session, storage: FileStore, race_id: int, car: str) -> tuple[Log, str | None]:
    race = session.get(Race, race_id)
    if race is None or race.trace_sha256 is None:
        raise HTTPException(404, f"Race {race_id} not found, or it has no trace.")
    row = next((c for c in race.cars if c.car_name == car), None)
    if row is None:
        raise HTTPException(404, f"Race {race_id} has no car {car!r}.")
    try:
        trace = json.loads(storage.read("traces", race.trace_sha256))
    except FileNotFoundError:
        raise HTTPException(404, f"The trace file of race {race_id} is missing.") from None
    log = race_log(race.config, trace, car)
    return log, model_reward_source(storage, _model(session, row))


def _model(session: Session, row: RaceCar) -> Model | None:
    return session.get(Model, row.model_id) if row.model_id is not None else None


def _job(
    session: Session, storage: FileStore, racer: Racer, job_id: int, episode: int | None
) -> Log:
    job = session.get(TrainingJob, job_id)
    if job is None or (racer.role != "admin" and job.owner_id != racer.id):
        raise HTTPException(404, f"Training job {job_id} not found among your jobs.")
    if job.run_sha256 is None:
        raise HTTPException(409, f"Training job {job_id} has no stored run yet.")
    try:
        data = storage.read("runs", job.run_sha256)
    except FileNotFoundError:
        raise HTTPException(404, f"The run of training job {job_id} is missing.") from None
    return run_log(data, trains_on(job.spec), episode)


def _log(
    session: Session, storage: FileStore, racer: Racer, body: RescoreCreate
) -> tuple[Log, str | None]:
    """The logged steps the body names and the model's own reward source (races only)."""
    if body.race_id is not None:
        log, original = _race(session, storage, body.race_id, body.car or "")
    else:
        assert body.training_job_id is not None
        log, original = _job(session, storage, racer, body.training_job_id, body.episode), None
    check_track(log)
    return log, original


@router.post("/rescore", response_model=RescoreOut, responses=ERRORS)
async def rescore(
    body: RescoreCreate,
    request: Request,
    racer: CurrentRacer,
    session: SessionDep,
    settings: SettingsDep,
    storage: StorageDep,
) -> RescoreOut:
    """Re-score a logged run with ``reward_source``: every control step of ``car`` in
    race ``race_id`` (any race), or of an episode of your training job's simtrace
    (``episode`` null: its last evaluation). The reward runs in the sandbox on the
    DeepRacer params rebuilt from the log (``docs/training-jobs.md``); ``original`` is the
    logged reward (training) or the model's own reward function's (a race whose model
    includes one), else null."""
    refused = await run_in_threadpool(training_refused, settings)
    if refused:
        raise HTTPException(503, refused)
    try:
        log, original = await run_in_threadpool(_log, session, storage, racer, body)
        async with request.app.state.training_checks:
            reward, scored = await run_in_threadpool(
                score_in_sandbox, settings, log, body.reward_source, original
            )
    except RescoreRefused as exc:
        raise HTTPException(422, str(exc)) from None
    except SandboxUnavailable as exc:
        raise HTTPException(503, str(exc)) from None
    return RescoreOut.model_validate(answer(log, reward, log.logged or scored))
