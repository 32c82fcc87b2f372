"""Evaluation workers: lease a job, race it in the sandbox, record the result exactly once.

One worker process runs one race at a time and is single-threaded (it forks the race child,
so it must be). Races run in a warm sandbox child
(:class:`league.jobs.sandbox.WarmSandbox`) forked once and reused for up to
:data:`RACES_PER_CHILD` races, each under its own limits and in a fresh env.
``slipstream league worker --concurrency N`` runs a small supervisor that starts N such
processes (``python -m league.jobs.worker``) with one BLAS/OpenMP thread each and restarts
any that die. While a race runs the worker heartbeats its lease; the result, its per-car
rows, the trace and the rating update are written in one transaction that begins by marking
the job done *if this lease still holds it*, so a worker whose lease expired can never
record a second result. A result whose trace cannot be stored (disk full, read-only) fails
that attempt with the ``OSError`` on the job, which is requeued while attempts remain; the
worker carries on. A model file that no longer matches its sha256 is not raced: its job
fails.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Mapping
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from arena.race import RaceResult, run_race
from league import crud
from league.jobs.daemon import LeasingDaemon
from league.jobs.evaluation import (
    EntrySuspended,
    RacePlan,
    build_plan,
    decode_plan,
    encode_plan,
    policies,
)
from league.jobs.faults import suspend_faulty
from league.jobs.queue import (
    DB_ERRORS,
    Backoff,
    Lease,
    claim_done,
    expire_leases,
    fail_job,
    heartbeat,
    lease_job,
)
from league.jobs.sandbox import SandboxError, SandboxLimits, WarmSandbox, one_thread_env
from league.models import Entry, Event, Job, Race
from league.ranking import rate_race
from league.settings import Settings
from league.store.base import FileStore, StorageError
from submissions.validator import DEFAULT_LIMITS

log = logging.getLogger("slipstream.worker")
RACES_PER_CHILD = 50
"""Races one warm sandbox child runs before it is replaced."""
CHILD_HIGH_WATER_MB = 256
"""Address space a warm child may gain over its size at fork before it is replaced."""


class LeaseLost(RuntimeError):
    """The job's lease expired and someone else may hold it: drop this race."""


def race_answer(plan: RacePlan) -> dict[str, Any]:
    """Run the planned race (in the sandboxed child) and return it as JSON-ready data."""
    return run_race(plan.config, policies(plan), record_trace=True, guard=plan.guard()).to_dict()


def answer_request(request: bytes) -> dict[str, Any]:
    """The warm child's handler: race the plan :func:`league.jobs.evaluation.encode_plan` wrote."""
    return race_answer(decode_plan(request))


def record_result(
    session: Session,
    storage: FileStore,
    lease: Lease,
    result: RaceResult,
    entry_ids: Mapping[str, int],
    fault_limit: int | None = None,
) -> Race | None:
    """Store a leased job's race, its cars, trace and ratings in one transaction; commit.

    The transaction begins by marking the job done if ``lease`` still holds it
    (:func:`league.jobs.queue.claim_done`); if it does not, nothing is written and the answer
    is None. ``entry_ids`` maps the race's car names to the entries that drove them. With
    ``fault_limit``, an entry with that many fault DNFs in the event is suspended from it in
    the same transaction (:func:`league.jobs.faults.suspend_faulty`).
    """
    if not claim_done(session, lease):
        session.rollback()
        return None
    job = session.get_one(Job, lease.job_id)
    event = session.execute(
        select(Event).where(Event.id == job.event_id).with_for_update()
    ).scalar_one()
    entries = {name: session.get_one(Entry, entry_id) for name, entry_id in entry_ids.items()}
    race = crud.record_race(session, storage, event, result, entries, job_id=job.id, commit=False)
    if event.race_type == "head_to_model":
        rate_race(session, race)
    faulted = [entries[c.name] for c in result.cars if c.dnf_reason and c.name in entries]
    if fault_limit is not None and faulted:
        session.flush()
        for entry in suspend_faulty(session, faulted, fault_limit):
            log.warning("entry %d suspended: %s", entry.id, entry.suspension)
    session.commit()
    return race


class Worker(LeasingDaemon):
    """One evaluation worker bound to a database and a file store."""

    kind = "worker"

    def __init__(self, settings: Settings, name: str | None = None) -> None:
        super().__init__(settings, name)
        self.limits = SandboxLimits(
            memory_mb=settings.race_memory_mb,
            cpu_seconds=settings.race_cpu_seconds,
            wall_seconds=settings.race_wall_seconds,
        )
        self.sandbox = WarmSandbox(
            answer_request,
            self.limits,
            max_runs=RACES_PER_CHILD,
            high_water_mb=CHILD_HIGH_WATER_MB,
        )
        self.step_budget_ms = settings.race_step_budget_ms or DEFAULT_LIMITS.max_latency_ms

    def close(self) -> None:
        """Stop the warm race child, then release the database."""
        self.sandbox.close()
        super().close()

    def run_once(self) -> bool:
        """Expire stale leases, lease one job and process it; False when the queue is empty."""
        with self.sessions() as session:
            requeued, failed = expire_leases(session)
            if requeued or failed:
                log.info("expired leases: %d requeued, %d failed", requeued, failed)
            lease = lease_job(session, self.name, self.settings.lease_seconds)
        if lease is None:
            return False
        log.info("job %d leased (attempt %d)", lease.job_id, lease.attempt)
        self.process(lease)
        return True

    def process(self, lease: Lease) -> None:
        """Race a leased job and record its result, or fail it with a clear error."""
        try:
            with self.sessions() as session:
                plan = build_plan(
                    session,
                    self.storage,
                    session.get_one(Job, lease.job_id),
                    step_budget_ms=self.step_budget_ms,
                    step_window=self.settings.race_step_window,
                )
        except DB_ERRORS:
            raise
        except EntrySuspended as exc:  # suspended after this job was queued: not raced
            self._fail(lease, f"not raced: {exc}")
            return
        except StorageError as exc:  # the store is unreachable for now: try again later
            self._fail(lease, f"could not read a model file: {exc}", retry=True)
            return
        except Exception as exc:  # a bad stored model or ruleset: the job cannot run
            self._fail(lease, f"could not build the race: {exc}")
            return
        holder = [lease]
        try:
            data = self.sandbox.run(encode_plan(plan), self._ticker(holder))
        except LeaseLost:
            log.warning("job %d: lease lost mid-race; result dropped", lease.job_id)
            return
        except SandboxError as exc:
            self._fail(holder[0], f"{exc.kind}: {exc}")
            return
        try:
            result = RaceResult.from_dict(data)
        except (KeyError, TypeError, ValueError) as exc:
            self._fail(holder[0], f"error: the race answer was malformed ({exc})")
            return
        entry_ids = {car.name: car.entry_id for car in plan.cars if car.entry_id}
        try:
            recorded = self._retry_db(
                lambda s: (
                    record_result(
                        s, self.storage, holder[0], result, entry_ids, self.settings.fault_dnf_limit
                    )
                    is not None
                )
            )
        except StorageError as exc:  # disk full or read-only: a later attempt may succeed
            self._fail(holder[0], f"storage: {exc}", retry=True)
            return
        if recorded:
            log.info("job %d done", lease.job_id)
        else:
            log.warning("job %d: lease lost before recording; result dropped", lease.job_id)

    def _fail(self, lease: Lease, error: str, retry: bool = False) -> None:
        """Record ``error`` on the job and fail it for good (a race that cannot run will not
        run on a retry either), or with ``retry`` requeue it while attempts remain."""
        self._retry_db(lambda session: fail_job(session, lease, error, retry=retry))
        log.warning("job %d failed: %s", lease.job_id, error)

    def _ticker(self, holder: list[Lease]) -> Callable[[], None]:
        every = self.settings.lease_seconds / 3
        last = [time.monotonic()]

        def tick() -> None:
            if time.monotonic() - last[0] < every:
                return
            last[0] = time.monotonic()
            try:
                with self.sessions() as session:
                    renewed = heartbeat(session, holder[0], self.settings.lease_seconds)
            except DB_ERRORS as exc:  # keep racing; the result transaction decides
                log.warning("heartbeat failed (%s)", type(exc).__name__)
                return
            if renewed is None:
                raise LeaseLost(f"job {holder[0].job_id}")
            holder[0] = renewed

        return tick


def spawn(index: int) -> subprocess.Popen:
    """Start one worker process with one BLAS/OpenMP thread (settings from the environment)."""
    env = one_thread_env()
    name = f"{socket.gethostname()}-{os.getpid()}-{index}"
    return subprocess.Popen([sys.executable, "-m", "league.jobs.worker", "--name", name], env=env)


def supervise(concurrency: int) -> None:
    """Run ``concurrency`` worker processes; restart any that die; stop them on a signal."""
    stopping = []
    for stop_signal in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
        signal.signal(stop_signal, lambda *_: stopping.append(True))
    procs = [spawn(i) for i in range(concurrency)]
    backoff = Backoff(cap=30.0)
    while not stopping:
        time.sleep(0.5)
        for i, proc in enumerate(procs):
            if proc.poll() is not None and not stopping:
                delay = backoff.next()
                log.warning(
                    "worker %d exited (%s); restarting in %.1f s", i, proc.returncode, delay
                )
                time.sleep(delay)
                procs[i] = spawn(i)
    for proc in procs:
        proc.send_signal(signal.SIGTERM)
    for proc in procs:
        proc.wait()


def main(argv: list[str] | None = None) -> None:
    """``python -m league.jobs.worker [--name NAME]``: one worker process (settings from env)."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("--name", default=None)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    Worker(Settings(), args.name).run_forever()


if __name__ == "__main__":
    main()
