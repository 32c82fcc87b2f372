"""Workers against a faulty file store: a full disk (a real 2 MiB tmpfs) and a model file
replaced on disk. SQLite and PostgreSQL."""

from __future__ import annotations

from sqlalchemy import func, select

from league.jobs.worker import Worker
from league.models import Job, Race
from tests.diskfull import fill, small_tmpfs
from tests.league_ops.conftest import Ops
from tests.league_ops.helpers import enter, event, model, racer, wait_until
from tests.league_ops.test_worker import drain


def _jobs(ops: Ops) -> dict[int, Job]:
    with ops.sessions() as session:
        return {job.entry_id: job for job in session.scalars(select(Job))}


def _races(ops: Ops) -> int:
    with ops.sessions() as session:
        return session.scalar(select(func.count(Race.id)))


def test_a_full_disk_fails_the_job_with_the_os_error_and_the_worker_keeps_running(
    ops: Ops,
) -> None:
    with small_tmpfs(ops.settings.storage_dir):
        ev = event(ops, seeds=[0])
        first = enter(ops, ev, model(ops, racer(ops, "ada")))
        filler = fill(ops.settings.storage_dir)
        worker = ops.start("worker", "w1")
        wait_until(
            lambda: _jobs(ops)[first.id].status == "failed" or worker.poll() is not None,
            timeout=120,
            what="the job to fail",
        )
        assert worker.poll() is None, ops.log("w1")
        job = _jobs(ops)[first.id]
        assert job.attempts == job.max_attempts == 3  # retried: space may come back
        assert job.error == (
            "storage: could not store a traces file: OSError: No space left on device"
        )
        assert _races(ops) == 0
        # space comes back: the same worker process races the next job
        filler.unlink()
        second = enter(ops, ev, model(ops, racer(ops, "bea"), seed=1))
        wait_until(lambda: _jobs(ops)[second.id].status == "done", 60, "the next job")
        assert worker.poll() is None and _races(ops) == 1


def test_a_model_file_replaced_on_disk_is_not_raced(ops: Ops) -> None:
    ev = event(ops, seeds=[0])
    stored = model(ops, racer(ops, "ada"), seed=0)
    substitute = model(ops, racer(ops, "eve"), seed=1)  # a valid model, other weights
    entry = enter(ops, ev, stored)
    path = ops.storage.path("models", stored.sha256)
    path.write_bytes(ops.storage.path("models", substitute.sha256).read_bytes())
    drain(Worker(ops.settings, "w1"))
    job = _jobs(ops)[entry.id]
    assert job.status == "failed" and job.attempts == 1
    assert job.error == (
        f"could not build the race: stored model file {stored.id} does not match its sha256;"
        " refusing to race it"
    )
    assert _races(ops) == 0
