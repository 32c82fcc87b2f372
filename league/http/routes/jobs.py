"""``/api/jobs``: the state of queued evaluation jobs."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Path
from sqlalchemy import select

from league.http.auth import CurrentRacer
from league.http.deps import SessionDep
from league.models import Entry, Job, Race
from league.schemas import MAX_ID, ErrorOut, JobOut

router = APIRouter(prefix="/api/jobs", tags=["jobs"])


@router.get("/{job_id}", response_model=JobOut, responses={404: {"model": ErrorOut}})
def read_job(
    job_id: Annotated[int, Path(ge=1, le=MAX_ID)], racer: CurrentRacer, session: SessionDep
) -> JobOut:
    """A job of one of your entries (admins: any job; round jobs: any racer)."""
    job = session.get(Job, job_id)
    if job is not None and racer.role != "admin" and job.entry_id is not None:
        owner = session.scalar(select(Entry.racer_id).where(Entry.id == job.entry_id))
        if owner != racer.id:
            job = None
    if job is None:
        raise HTTPException(404, f"Job {job_id} not found among your jobs.")
    race_id = session.scalar(select(Race.id).where(Race.job_id == job.id))
    return JobOut.model_validate(job).model_copy(update={"race_id": race_id})
