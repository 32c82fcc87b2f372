"""``/api/models``: upload a submission (validated by ``submissions``) and read models."""

from __future__ import annotations

import re
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Annotated, Any

from fastapi import (
    APIRouter,
    Depends,
    File,
    Form,
    HTTPException,
    Path,
    Request,
    Response,
    UploadFile,
)
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse
from pydantic import TypeAdapter, ValidationError
from sqlalchemy import Select, select
from sqlalchemy.orm import Session

from league import crud
from league.http.auth import CurrentRacer, OptionalRacer
from league.http.deps import SessionDep, SettingsDep, StorageDep
from league.http.upload_validation import (
    RETRY_AFTER_SECONDS,
    RacerUploadLimit,
    UploadValidator,
    ValidationBusy,
)
from league.models import Entry, Event, Model, Racer
from league.schemas import MAX_ID, ErrorOut, ModelName, ModelOut, ModelSuspension
from league.store.base import FileStore
from submissions import ValidationReport

router = APIRouter(prefix="/api/models", tags=["models"])
ModelId = Annotated[int, Path(ge=1, le=MAX_ID)]
MODEL_NAME = TypeAdapter(ModelName)


def suspensions(
    session: Session, model_ids: list[int] | Select
) -> dict[int, list[ModelSuspension]]:
    """Per model id (a list, or a query of ids), the events its entries were suspended from
    (:mod:`league.jobs.faults`), in one query."""
    rows = session.execute(
        select(Entry, Event.name)
        .join(Event, Entry.event_id == Event.id)
        .where(Entry.model_id.in_(model_ids), Entry.suspended_at.is_not(None))
        .order_by(Entry.suspended_at)
    )
    found: dict[int, list[ModelSuspension]] = {}
    for entry, name in rows:
        found.setdefault(entry.model_id, []).append(
            ModelSuspension(
                event_id=entry.event_id,
                event_name=name,
                entry_id=entry.id,
                suspended_at=entry.suspended_at,
                message=entry.suspension or "",
            )
        )
    return found


def model_out(
    model: Model, owner_view: bool, suspended: list[ModelSuspension] | None = None
) -> ModelOut:
    """The API view of a model: everything for its owner (with ``suspended``, the events it
    was suspended from), the public fields otherwise."""
    info = model.info
    private: dict[str, Any] = {}
    if owner_view:
        private = {"sha256": model.sha256, "size": model.size, "info": info}
        private["suspensions"] = suspended or []
    return ModelOut(
        id=model.id,
        name=model.name,
        owner=model.owner.alias,
        visibility="owner" if owner_view else "public",
        action_space_type=str(info.get("action_space", {}).get("type", "unknown")),
        sensors=list(info.get("sensors", [])),
        created_at=model.created_at,
        **private,
    )


def _name(given: str | None, filename: str | None) -> str:
    if given is not None:
        try:
            return MODEL_NAME.validate_python(given)
        except ValidationError as exc:
            raise HTTPException(422, f"name: {exc.errors()[0]['msg']}") from None
    stem = re.sub(r"[^A-Za-z0-9_.\-]", "_", (filename or "model").rsplit(".", 1)[0])[:64]
    return stem or "model"


VALIDATION_REFUSALS: dict[int | str, dict[str, Any]] = {
    422: {"model": ErrorOut, "description": "The validator's problems"},
    429: {"model": ErrorOut, "description": "Your other uploads are still being validated"},
    503: {"model": ErrorOut, "description": "Validation is busy; retry after Retry-After s"},
}
"""The answers of a route that validates a model archive, beside its own."""


def upload_validator(request: Request) -> UploadValidator:
    """The app's validator of model archives (a dependency)."""
    return request.app.state.upload_validator


@asynccontextmanager
async def validation_slot(validator: UploadValidator, racer_id: int) -> AsyncIterator[None]:
    """A validation slot for ``racer_id``: 503 with Retry-After when all are busy, 429 when
    the racer already has as many validating or waiting as one racer may."""
    try:
        async with validator.slot(racer_id):
            yield
    except ValidationBusy as exc:
        headers = {"Retry-After": str(RETRY_AFTER_SECONDS)}
        status = 429 if isinstance(exc, RacerUploadLimit) else 503
        raise HTTPException(status, f"{exc} Try again later.", headers=headers) from None


async def stored(
    report: ValidationReport,
    session: Session,
    storage: FileStore,
    owner: Racer,
    name: str,
    data: bytes,
    response: Response,
) -> ModelOut | JSONResponse:
    """``data`` stored as one of ``owner``'s models when the validator accepted it (201;
    200 when the owner has it already), else the 422 answer with the problems."""
    if not report.ok or report.info is None:
        return JSONResponse(
            status_code=422,
            content={
                "detail": f"The model file was refused: {len(report.problems)} problem(s) found.",
                "problems": [p.model_dump() for p in report.problems],
            },
        )
    model, new = await run_in_threadpool(
        crud.add_model, session, storage, owner, name, data, report.info
    )
    if not new:
        response.status_code = 200
    return await run_in_threadpool(model_out, model, True)


@router.post(
    "",
    status_code=201,
    response_model=ModelOut,
    responses={
        200: {"model": ModelOut, "description": "The same file was uploaded before"},
        413: {"model": ErrorOut, "description": "File too large"},
        **VALIDATION_REFUSALS,
    },
)
async def upload_model(
    file: Annotated[UploadFile, File(description="A submission archive (.zip)")],
    racer: CurrentRacer,
    session: SessionDep,
    settings: SettingsDep,
    storage: StorageDep,
    validator: Annotated[UploadValidator, Depends(upload_validator)],
    response: Response,
    name: Annotated[str | None, Form(description="Display name; default: the file name")] = None,
) -> ModelOut | JSONResponse:
    """Upload a model. It is validated in a child process (a few at once: 503 with
    Retry-After when all are busy, 429 when you already have as many uploads validating or
    waiting as one racer may); the same file twice gives the same model (200)."""
    model_name = _name(name, file.filename)
    async with validation_slot(validator, racer.id):
        data = await file.read(settings.max_upload_bytes + 1)
        if len(data) > settings.max_upload_bytes:
            limit = settings.max_upload_bytes
            raise HTTPException(413, f"The model file is over the limit of {limit} bytes.")
        report = await validator.validate(data)
    return await stored(report, session, storage, racer, model_name, data, response)


@router.get("", response_model=list[ModelOut])
def list_models(racer: CurrentRacer, session: SessionDep) -> list[ModelOut]:
    """Your models (admins see everyone's), newest first."""
    query = select(Model).order_by(Model.id.desc())
    if racer.role != "admin":
        query = query.where(Model.owner_id == racer.id)
    models = list(session.scalars(query))
    suspended = suspensions(session, query.with_only_columns(Model.id).order_by(None))
    return [model_out(m, owner_view=True, suspended=suspended.get(m.id)) for m in models]


@router.get("/{model_id}", response_model=ModelOut, responses={404: {"model": ErrorOut}})
def read_model(model_id: ModelId, racer: OptionalRacer, session: SessionDep) -> ModelOut:
    """A model: in full for its owner or an admin; public fields of an entered model else."""
    model = session.get(Model, model_id)
    if model is not None and _owns(racer, model):
        suspended = suspensions(session, [model.id]).get(model.id)
        return model_out(model, owner_view=True, suspended=suspended)
    if model is not None and crud.is_entered(session, model.id):
        return model_out(model, owner_view=False)
    raise HTTPException(404, f"Model {model_id} not found.")


def _owns(racer: Racer | None, model: Model) -> bool:
    return racer is not None and (racer.role == "admin" or racer.id == model.owner_id)
