"""Owner-only JSON behind the model page: a model's races and its training metrics."""

from __future__ import annotations

import csv
import io
import math
import zipfile
from typing import Annotated

from fastapi import APIRouter, HTTPException, Path
from pydantic import BaseModel
from sqlalchemy.orm import Session

from league.http.auth import CurrentRacer
from league.http.deps import SessionDep, StorageDep
from league.models import Model, Racer
from league.schemas import MAX_ID, ErrorOut
from league.web.queries import ModelRace, model_races
from submissions.format import METRICS_MEMBER

router = APIRouter(prefix="/api/models", tags=["models"])
ModelId = Annotated[int, Path(ge=1, le=MAX_ID)]
NOT_FOUND = {404: {"model": ErrorOut, "description": "Not one of your models, or no metrics"}}
MAX_METRIC_ROWS = 20_000


class Metrics(BaseModel):
    """The model's ``metrics.csv``: column names and one list of values per column."""

    columns: list[str]
    values: dict[str, list[float | None]]


def owned_model(session: Session, racer: Racer, model_id: int) -> Model:
    """The model if ``racer`` owns it (admins: any model), else a 404."""
    model = session.get(Model, model_id)
    if model is None or (racer.role != "admin" and model.owner_id != racer.id):
        raise HTTPException(404, f"Model {model_id} is not one of your models.")
    return model


@router.get("/{model_id}/races", response_model=list[ModelRace], responses=NOT_FOUND)
def read_model_races(
    model_id: ModelId, racer: CurrentRacer, session: SessionDep
) -> list[ModelRace]:
    """Your model's results history, newest first."""
    model = owned_model(session, racer, model_id)
    return model_races(session, model)


def _number(text: str | None) -> float | None:
    try:
        value = float(text or "")
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def parse_metrics(data: bytes) -> Metrics:
    """Columns of a metrics CSV as numbers (blank or non-numeric cells become null)."""
    reader = csv.DictReader(io.StringIO(data.decode("utf-8", "replace")))
    columns = [c for c in reader.fieldnames or [] if c]
    values: dict[str, list[float | None]] = {c: [] for c in columns}
    for index, row in enumerate(reader):
        if index >= MAX_METRIC_ROWS:
            break
        for column in columns:
            values[column].append(_number(row.get(column)))
    return Metrics(columns=columns, values=values)


@router.get("/{model_id}/metrics", response_model=Metrics, responses=NOT_FOUND)
def read_model_metrics(
    model_id: ModelId, racer: CurrentRacer, session: SessionDep, storage: StorageDep
) -> Metrics:
    """Your model's training metrics (from the ``metrics.csv`` in its archive)."""
    model = owned_model(session, racer, model_id)
    if not model.info.get("has_metrics"):
        raise HTTPException(404, f"Model {model_id} was uploaded without training metrics.")
    try:
        with zipfile.ZipFile(io.BytesIO(storage.read("models", model.sha256))) as archive:
            data = archive.read(METRICS_MEMBER)
    except (FileNotFoundError, KeyError, zipfile.BadZipFile):
        raise HTTPException(404, f"The metrics of model {model_id} cannot be read.") from None
    return parse_metrics(data)
