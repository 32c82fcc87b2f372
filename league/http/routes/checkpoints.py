"""``/api/training-jobs/{id}/checkpoints``: choose which of a run's checkpoints to keep as a
model (by completion, by lap time, or the last), as DeepRacer racers choose a checkpoint.

A job's own model is its ``best`` checkpoint; the run zip holds each checkpoint packed
(:mod:`league.training.checkpoints`). Making one a model validates it as an upload is (and
as the trainer validates the job's own model), under the upload limit.
"""

from __future__ import annotations

import hashlib
from typing import Annotated

from fastapi import APIRouter, Depends, HTTPException, Path, Response
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse
from pydantic import Field
from sqlalchemy import select

from agents.checkpoint import Which
from league.http.auth import CurrentRacer
from league.http.deps import SessionDep, SettingsDep, StorageDep
from league.http.routes.models import (
    VALIDATION_REFUSALS,
    stored,
    upload_validator,
    validation_slot,
)
from league.http.routes.training import JobId, visible_job
from league.http.upload_validation import UploadValidator
from league.models import Model, TrainingJob
from league.schemas import ErrorOut, ModelOut
from league.settings import MiB
from league.store.base import FileStore
from league.training.checkpoints import (
    CheckpointMissing,
    CheckpointOut,
    checkpoint_archive,
    list_checkpoints,
)

router = APIRouter(prefix="/api/training-jobs", tags=["training"])
CheckpointName = Annotated[Which, Path(description="best, fastest or last")]


class TrainingCheckpointOut(CheckpointOut):
    """A checkpoint of a job's run, and the model made of it, if any."""

    model_id: int | None = Field(description="The owner's model holding this checkpoint")


def _run_zip(job: TrainingJob, storage: FileStore) -> bytes:
    if job.run_sha256 is None:
        raise HTTPException(404, f"Training job {job.id} has no stored run yet.")
    return storage.read("runs", job.run_sha256)


def _archive(run_zip: bytes, job: TrainingJob, name: Which, limit: int) -> bytes:
    try:
        return checkpoint_archive(run_zip, name, limit)
    except CheckpointMissing:
        raise HTTPException(404, f"Training job {job.id}'s run has no {name} checkpoint.") from None
    except ValueError as exc:
        raise HTTPException(422, f"The {name} checkpoint cannot be read: {exc}") from None


@router.get(
    "/{job_id}/checkpoints",
    response_model=list[TrainingCheckpointOut],
    responses={404: {"model": ErrorOut}, 422: {"model": ErrorOut}},
)
def read_checkpoints(
    job_id: JobId,
    racer: CurrentRacer,
    session: SessionDep,
    settings: SettingsDep,
    storage: StorageDep,
) -> list[TrainingCheckpointOut]:
    """The checkpoints the job's stored run offers (none while it runs), each with the
    evaluation it was kept for and the model made of it."""
    job = visible_job(session, racer, job_id)
    if job.run_sha256 is None:
        return []
    data = _run_zip(job, storage)
    try:
        kept = list_checkpoints(data)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    bound = settings.training_disk_mb * MiB  # what the run folder could hold
    digests = {c.name: hashlib.sha256(_archive(data, job, c.name, bound)).hexdigest() for c in kept}
    owned = select(Model.sha256, Model.id).where(
        Model.owner_id == job.owner_id, Model.sha256.in_(list(digests.values()))
    )
    models = {sha: model_id for sha, model_id in session.execute(owned)}
    return [
        TrainingCheckpointOut(**c.model_dump(), model_id=models.get(digests[c.name])) for c in kept
    ]


@router.post(
    "/{job_id}/checkpoints/{name}/model",
    status_code=201,
    response_model=ModelOut,
    responses={
        200: {"model": ModelOut, "description": "This checkpoint is already a model"},
        404: {"model": ErrorOut},
        **VALIDATION_REFUSALS,
    },
)
async def model_from_checkpoint(
    job_id: JobId,
    name: CheckpointName,
    racer: CurrentRacer,
    session: SessionDep,
    settings: SettingsDep,
    storage: StorageDep,
    validator: Annotated[UploadValidator, Depends(upload_validator)],
    response: Response,
) -> ModelOut | JSONResponse:
    """Make checkpoint ``name`` of the job's run one of the job owner's models, validated
    as an upload is; the same checkpoint twice gives the same model (200)."""
    job = await run_in_threadpool(visible_job, session, racer, job_id)
    run_zip = await run_in_threadpool(_run_zip, job, storage)
    data = _archive(run_zip, job, name, settings.max_upload_bytes)
    async with validation_slot(validator, racer.id):
        report = await validator.validate(data)
    model_name = f"{job.name[: 63 - len(name)]}-{name}"
    return await stored(report, session, storage, job.owner, model_name, data, response)
