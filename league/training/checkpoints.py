"""The checkpoints a stored training run offers as models, read from its run zip.

A job's child packs each checkpoint of its run as a submission in ``run/models/``
(:meth:`agents.run.Run.pack_checkpoints`): ``best`` (by completion, the job's own model),
``fastest`` (by evaluation lap) and ``last``, listed in ``models/index.json``. The run
folder is written by the racer's code, so both are read as untrusted input: sizes checked
before anything is decompressed, the index validated, and an archive becomes a model only
after the upload validator accepts it.
"""

from __future__ import annotations

import io
import json
import zipfile

from pydantic import BaseModel, Field, TypeAdapter, ValidationError

from agents.checkpoint import CHECKPOINT_INDEX, CHECKPOINTS, Which
from agents.train_job import CHECKPOINT_MODELS_DIR

MAX_INDEX_BYTES = 16 * 1024


class CheckpointOut(BaseModel):
    """One checkpoint of a run, packed as a submission."""

    name: Which
    by: str = Field(description="What this checkpoint is the best by")
    iteration: int = Field(ge=0)
    minutes: float = Field(ge=0, description="Training time when it was taken")
    completion: float | None = Field(
        None, ge=0, le=100, description="Its evaluation's completion (%); None for last"
    )
    best_lap: float | None = Field(None, gt=0, description="Its evaluation's best lap (s)")


_INDEX = TypeAdapter(list[CheckpointOut])


class CheckpointMissing(LookupError):
    """The run holds no such checkpoint archive (or none at all)."""


def _member(archive: zipfile.ZipFile, name: str, limit: int) -> bytes:
    """The member ``name``, refused past ``limit`` bytes before it is decompressed (a
    member never yields more than the size it declares: ``zipfile`` stops there)."""
    try:
        info = archive.getinfo(name)
    except KeyError:
        raise CheckpointMissing(name) from None
    if info.file_size > limit:
        raise ValueError(f"{name} is {info.file_size} bytes, over the limit of {limit}")
    try:
        return archive.read(info)
    except zipfile.BadZipFile as exc:
        raise ValueError(f"{name} cannot be read: {exc}") from None


def _open(run_zip: bytes) -> zipfile.ZipFile:
    try:
        return zipfile.ZipFile(io.BytesIO(run_zip))
    except zipfile.BadZipFile as exc:
        raise ValueError(f"the stored run is not a zip: {exc}") from None


def list_checkpoints(run_zip: bytes) -> list[CheckpointOut]:
    """The checkpoints listed in a run zip's index, in :data:`CHECKPOINTS` order; empty
    when the run packed none (it ended before its first iteration, or predates them)."""
    with _open(run_zip) as archive:
        try:
            raw = _member(archive, f"{CHECKPOINT_MODELS_DIR}/{CHECKPOINT_INDEX}", MAX_INDEX_BYTES)
        except CheckpointMissing:
            return []
        names = set(archive.namelist())
    try:
        listed = _INDEX.validate_python(json.loads(raw))
    except (ValueError, ValidationError) as exc:
        raise ValueError(f"the run's checkpoint index is unreadable: {exc}") from None
    found = {c.name: c for c in listed if f"{CHECKPOINT_MODELS_DIR}/{c.name}.zip" in names}
    return [found[name] for name in CHECKPOINTS if name in found]


def checkpoint_archive(run_zip: bytes, name: Which, limit: int) -> bytes:
    """The submission archive packed from checkpoint ``name`` (at most ``limit`` bytes);
    :class:`CheckpointMissing` when the run has none, ValueError when it is too large."""
    with _open(run_zip) as archive:
        return _member(archive, f"{CHECKPOINT_MODELS_DIR}/{name}.zip", limit)
