"""Owner-only JSON behind the model page: a model's races and its training metrics.

A metrics reply is small by construction: ``submissions.metrics_csv.read_metrics`` reads
within the format's bounds and downsamples each column to at most ``MAX_METRIC_POINTS``
points. Replies are kept per archive digest (archives never change) in a bounded cache.
"""

from __future__ import annotations

import io
import threading
import zipfile
from collections import OrderedDict
from typing import Annotated

from fastapi import APIRouter, HTTPException, Path
from pydantic import BaseModel
from sqlalchemy.orm import Session

from league.http.auth import CurrentRacer
from league.http.deps import SessionDep, StorageDep
from league.models import Model, Racer
from league.schemas import MAX_ID, ErrorOut
from league.store.base import FileStore
from league.web.queries import ModelRace, model_races
from submissions.format import METRICS_MEMBER
from submissions.metrics_csv import read_metrics
from submissions.validator import DEFAULT_LIMITS

router = APIRouter(prefix="/api/models", tags=["models"])
ModelId = Annotated[int, Path(ge=1, le=MAX_ID)]
NOT_FOUND = {404: {"model": ErrorOut, "description": "Not one of your models, or no metrics"}}
MAX_METRIC_POINTS = 500
CACHED_REPLIES = 32


class Metrics(BaseModel):
    """The model's ``metrics.csv``: column names, one list of values per column (at most
    ``MAX_METRIC_POINTS`` each, downsampled) and the number of rows in the file."""

    columns: list[str]
    values: dict[str, list[float | None]]
    rows: int


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


def parse_metrics(data: bytes) -> Metrics:
    """A metrics CSV as numbers (blank or non-numeric cells null), bounded and downsampled."""
    series = read_metrics(data, DEFAULT_LIMITS, MAX_METRIC_POINTS)
    return Metrics(columns=series.columns, values=series.values, rows=series.rows)


class _Replies:
    """The last ``CACHED_REPLIES`` metrics replies, by archive digest."""

    def __init__(self) -> None:
        self._replies: OrderedDict[str, Metrics] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, sha256: str) -> Metrics | None:
        with self._lock:
            reply = self._replies.get(sha256)
            if reply is not None:
                self._replies.move_to_end(sha256)
            return reply

    def put(self, sha256: str, reply: Metrics) -> None:
        with self._lock:
            self._replies[sha256] = reply
            while len(self._replies) > CACHED_REPLIES:
                self._replies.popitem(last=False)


_REPLIES = _Replies()


def _metrics_bytes(storage: FileStore, sha256: str) -> bytes:
    """The archive's ``metrics.csv``, decompressed no further than the format's cap."""
    cap = DEFAULT_LIMITS.max_metrics_bytes
    archive = zipfile.ZipFile(io.BytesIO(storage.read("models", sha256)))
    with archive, archive.open(METRICS_MEMBER) as member:
        return member.read(cap)


@router.get("/{model_id}/metrics", response_model=Metrics, responses=NOT_FOUND)
def read_model_metrics(
    model_id: ModelId, racer: CurrentRacer, session: SessionDep, storage: StorageDep
) -> Metrics:
    """Your model's training metrics (from the ``metrics.csv`` in its archive)."""
    model = owned_model(session, racer, model_id)
    if not model.info.get("has_metrics"):
        raise HTTPException(404, f"Model {model_id} was uploaded without training metrics.")
    reply = _REPLIES.get(model.sha256)
    if reply is None:
        try:
            data = _metrics_bytes(storage, model.sha256)
        except (FileNotFoundError, KeyError, zipfile.BadZipFile):
            raise HTTPException(404, f"The metrics of model {model_id} cannot be read.") from None
        reply = parse_metrics(data)
        _REPLIES.put(model.sha256, reply)
    return reply
