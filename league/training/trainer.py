"""Trainers: lease a training job, run it in the sandbox, report it live, store what it made.

``slipstream league trainer`` runs one :class:`Trainer` (one job at a time; start several,
on any hosts sharing the database and file store, for more). For each leased job it lays
out a working folder (``job.json``, ``reward.py``, a clone's parent run), starts
``python -m agents.train_job`` there in the sandbox (:mod:`league.training.launch`) and,
while it runs, turns each line it prints into a job event, heartbeats the lease, and
watches the budget, the folder's size and stop requests. A stop asks the child to finish
(a ``STOP`` file it polls): it keeps what it trained. When the child ends, the run folder
goes to the file store as a zip, its model is validated as an upload is and becomes one of
the racer's models, and the job ends ``done`` or ``stopped``; or the job fails with the
reason (out of memory or CPU time, a folder over its size, the reward raising, ...).

A trainer stopped by a signal kills its child and gives the job back to the queue. One
killed outright (SIGKILL) takes its child with it (the sandbox dies with its parent) and
stops heartbeating, so the job's lease expires and another trainer takes it, or it fails
once its attempts are spent (:func:`league.training.queue.expire_training_leases`).
"""

from __future__ import annotations

import asyncio
import csv
import io
import logging
import os
import queue
import shutil
import signal
import threading
import time
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from agents.train_job import PARENT_DIR, RUN_DIR, STOP_FILE, read_record
from league import crud
from league.http.upload_validation import UploadValidator
from league.jobs.daemon import LeasingDaemon
from league.jobs.queue import DB_ERRORS
from league.models import Racer, TrainingJob
from league.settings import Settings
from league.training.launch import limits_of, start_child, stop_child
from league.training.queue import (
    TrainingLease,
    expire_training_leases,
    finish_training,
    give_back,
    heartbeat_training,
    lease_training,
    report,
)
from league.training.sandbox import SandboxUnavailable
from league.training.spec import write_workdir

log = logging.getLogger("slipstream.trainer")
START_GRACE_S = 120.0
"""Time past its budget a job may take (start-up, the last evaluation, packing)."""
STOP_GRACE_S = 60.0
"""Time a job asked to stop may take to save its work before it is killed."""
MAX_LINE = 4000
MAX_LOG_LINES = 5000
"""Log lines one job may store; later ones are counted, not kept."""
DISK_CHECK_S = 2.0
MAX_POSES = 600
"""Poses of a training race sent to the live view per iteration (every step up to it)."""
MAX_SIMTRACE_BYTES = 8 * 1024 * 1024
MEMORY_WORDS = ("MemoryError", "Cannot allocate memory", "std::bad_alloc")


def job_machine(settings: Settings) -> dict[str, int | None]:
    """Env workers and torch threads of one job: the host's cores shared among the jobs
    that may run at once (``training_workers`` when set; threads as ``slipstream train``
    picks them when one job has the host to itself)."""
    share = max(1, (os.cpu_count() or 1) // settings.training_jobs_total)
    workers = share if settings.training_workers is None else settings.training_workers
    return {"workers": workers, "threads": share if settings.training_jobs_total > 1 else None}


def folder_bytes(path: Path) -> int:
    """Bytes of the files under ``path`` (what the disk watchdog counts)."""
    total = 0
    for root, _dirs, files in os.walk(path):
        for name in files:
            try:
                total += os.lstat(os.path.join(root, name)).st_size
            except OSError:
                continue
    return total


def zip_folder(path: Path) -> bytes:
    """``path``'s files as a deflated zip (names relative to it)."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for file in sorted(p for p in path.rglob("*") if p.is_file() and not p.is_symlink()):
            archive.write(file, file.relative_to(path).as_posix())
    return buffer.getvalue()


def unzip_run(data: bytes, target: Path) -> None:
    """Extract a stored run zip (the league's own) into ``target``, names kept inside it."""
    target.mkdir(parents=True)
    root = target.resolve()
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        for info in archive.infolist():
            destination = (root / info.filename).resolve()
            if not destination.is_relative_to(root):
                raise ValueError(f"stored run has an entry outside its folder: {info.filename}")
        archive.extractall(root)


@dataclass
class _Watch:
    """What the trainer saw of one running child."""

    why_killed: str | None = None
    stop_asked: bool = False
    done: dict | None = None
    log_lines: int = 0
    output_ended: bool = False
    tail: list[str] = field(default_factory=list)


class LeaseLost(RuntimeError):
    """Another trainer may hold the job now: drop it."""


class Trainer(LeasingDaemon):
    """One trainer bound to a database and a file store; one job at a time."""

    kind = "trainer"

    def __init__(self, settings: Settings, name: str | None = None) -> None:
        super().__init__(settings, name)
        self.machine = job_machine(settings)
        self.root = settings.data_dir / "training" / "jobs"

    def run_forever(self) -> None:
        """Train until stopped, behind the API and races on this host (``training_nice``)."""
        os.nice(self.settings.training_nice)
        log.info("a training job gets %s", self.machine)
        super().run_forever()

    def run_once(self) -> bool:
        """Expire stale leases, lease one job and run it; False when none may start."""
        with self.sessions() as session:
            requeued, failed = expire_training_leases(session)
            if requeued or failed:
                log.info("expired training leases: %d requeued, %d failed", requeued, failed)
            lease = lease_training(session, self.settings, self.name, self.settings.lease_seconds)
        if lease is None:
            return False
        log.info("training job %d leased (attempt %d)", lease.job_id, lease.attempt)
        self.process(lease)
        return True

    def process(self, lease: TrainingLease) -> None:
        """Run one leased job to its end (see the module docstring)."""
        workdir = self.root / f"{lease.job_id}-{lease.attempt}"
        shutil.rmtree(workdir, ignore_errors=True)
        started = time.monotonic()
        try:
            self._prepare(lease, workdir)
            self._run(lease, workdir, started)
        except LeaseLost:
            log.warning("training job %d: lease lost; dropped", lease.job_id)
        finally:
            shutil.rmtree(workdir, ignore_errors=True)

    # ---------------------------------------------------------------- steps
    def _prepare(self, lease: TrainingLease, workdir: Path) -> None:
        with self.sessions() as session:
            job = session.get_one(TrainingJob, lease.job_id)
            fields = {**job.spec, **self.machine}
            source = job.reward_source
            parent = session.get(TrainingJob, job.clone_of_id) if job.clone_of_id else None
            parent_run = parent.run_sha256 if parent is not None else None
        write_workdir(workdir, fields, source)
        if parent_run is not None:  # a resumed run goes on in place; a clone starts from it
            into = RUN_DIR if fields.get("resume") else PARENT_DIR
            unzip_run(self.storage.read("runs", parent_run), workdir / into)

    def _run(self, lease: TrainingLease, workdir: Path, started: float) -> None:
        with self.sessions() as session:
            minutes = session.get_one(TrainingJob, lease.job_id).minutes
        budget = minutes * 60.0 + START_GRACE_S
        cpu = int(budget * (self.machine["workers"] + (self.machine["threads"] or 2))) + 60
        try:
            child = start_child([], workdir, self.settings, limits_of(self.settings, cpu))
        except (SandboxUnavailable, OSError) as exc:
            self._end(lease, started, "failed", f"the trainer could not start the job: {exc}")
            return
        watch = _Watch()
        holder = [lease]
        lines = _reader(child)
        try:
            self._follow(child, lines, holder, watch, workdir, started + budget)
        finally:
            stop_child(child)
        if self.stopping and watch.why_killed == "trainer stopping":
            self._retry_db(lambda s: give_back(s, holder[0], self._ran(started), "trainer stopped"))
            return
        self._conclude(holder[0], child.returncode, watch, workdir, started)

    def _follow(
        self,
        child,
        lines: queue.Queue,
        holder: list[TrainingLease],
        watch: _Watch,
        workdir: Path,
        deadline: float,
    ) -> None:
        """Relay the child's lines, heartbeat, and enforce stop, budget and disk."""
        beat = self.settings.lease_seconds / 3
        next_beat = next_disk = time.monotonic()
        kill_at: float | None = None
        while True:
            pending = self._drain(lines, watch, workdir)
            if pending:
                self._report(holder[0], pending)
            if watch.output_ended and child.poll() is not None:
                return
            now = time.monotonic()
            if now >= next_beat:
                next_beat = now + beat
                renewed, stop = self._heartbeat(holder[0])
                if renewed is None:
                    stop_child(child)
                    raise LeaseLost(str(holder[0].job_id))
                holder[0] = renewed
                if stop and not watch.stop_asked:
                    watch.stop_asked = True
                    (workdir / STOP_FILE).touch()
                    kill_at = now + STOP_GRACE_S
            if self.stopping and watch.why_killed is None:
                watch.why_killed = "trainer stopping"
                stop_child(child)
            if now >= deadline and watch.why_killed is None:
                watch.why_killed = "it ran past its budget and did not stop"
                stop_child(child)
            if kill_at is not None and now >= kill_at and watch.why_killed is None:
                watch.why_killed = f"it did not stop within {STOP_GRACE_S:g} s of being asked"
                stop_child(child)
            if now >= next_disk:
                next_disk = now + DISK_CHECK_S
                limit = self.settings.training_disk_mb
                if folder_bytes(workdir) > limit * 1024 * 1024 and watch.why_killed is None:
                    watch.why_killed = f"its folder grew past {limit} MiB (training_disk_mb)"
                    stop_child(child)
            time.sleep(0.1)

    def _drain(self, lines: queue.Queue, watch: _Watch, workdir: Path) -> list[tuple[str, dict]]:
        events: list[tuple[str, dict]] = []
        while True:
            try:
                raw = lines.get_nowait()
            except queue.Empty:
                return events
            if raw is None:
                watch.output_ended = True
                continue
            text = raw.decode("utf-8", "replace").rstrip()[:MAX_LINE]
            record = read_record(text)
            if record is not None and record.get("type") == "iteration":
                record.pop("type")
                events.append(("iteration", record))
                poses = race_poses(workdir / RUN_DIR, record.get("iteration"))
                if poses is not None:
                    events.append(("poses", poses))
                continue
            if record is not None and record.get("type") == "done":
                watch.done = record
                continue
            watch.tail = [*watch.tail[-19:], text]
            watch.log_lines += 1
            if watch.log_lines <= MAX_LOG_LINES:
                events.append(("log", {"line": text}))
            elif watch.log_lines == MAX_LOG_LINES + 1:
                events.append(("log", {"line": f"(log lines past {MAX_LOG_LINES} not kept)"}))

    def _conclude(
        self, lease: TrainingLease, code: int | None, watch: _Watch, workdir: Path, started: float
    ) -> None:
        """Store what the child made and end the job, or fail it with the reason."""
        failure = _failure(code, watch, self.settings)
        model_zip = job_file(workdir, RUN_DIR, "model", "model.zip")
        if failure is not None or model_zip is None:
            why = failure or "the job ended without a model (it trained no iteration)"
            self._end(lease, started, "failed", why, workdir)
            return
        try:
            model_id = self._store_model(lease, model_zip)
        except ValueError as exc:
            self._end(lease, started, "failed", str(exc), workdir)
            return
        status = "stopped" if watch.stop_asked else "done"
        self._end(lease, started, status, None, workdir, model_id)

    def _store_model(self, lease: TrainingLease, model_zip: Path) -> int:
        """Validate the trained model as an upload is and add it to the racer's models."""
        data = model_zip.read_bytes()
        report = asyncio.run(UploadValidator(self.settings).validate(data))
        if not report.ok or report.info is None:
            problems = "; ".join(p.message for p in report.problems[:3])
            raise ValueError(f"the trained model failed validation: {problems}")
        with self.sessions() as session:
            job = session.get_one(TrainingJob, lease.job_id)
            owner = session.get_one(Racer, job.owner_id)
            model, _new = crud.add_model(session, self.storage, owner, job.name, data, report.info)
            return model.id

    def _end(
        self,
        lease: TrainingLease,
        started: float,
        status: str,
        error: str | None,
        workdir: Path | None = None,
        model_id: int | None = None,
    ) -> None:
        run = workdir / RUN_DIR if workdir is not None else None
        sha = None
        if run is not None and run.is_dir() and any(run.iterdir()):
            sha, _created = self.storage.put("runs", zip_folder(run))
        ran = self._ran(started)
        ended = self._retry_db(
            lambda s: finish_training(s, lease, status, ran, error, sha, model_id)
        )
        log.info("training job %d %s%s", lease.job_id, status, f": {error}" if error else "")
        if not ended:
            log.warning("training job %d: lease lost before it ended", lease.job_id)

    # ---------------------------------------------------------------- db
    def _report(self, lease: TrainingLease, events: list[tuple[str, dict]]) -> None:
        if not self._retry_db(lambda s: report(s, lease, events)):
            raise LeaseLost(str(lease.job_id))

    def _heartbeat(self, lease: TrainingLease) -> tuple[TrainingLease | None, bool]:
        try:
            with self.sessions() as session:
                return heartbeat_training(session, lease, self.settings.lease_seconds)
        except DB_ERRORS as exc:  # keep training; the lease decides later
            log.warning("heartbeat failed (%s)", type(exc).__name__)
            return lease, False

    @staticmethod
    def _ran(started: float) -> float:
        return time.monotonic() - started


def _reader(child) -> queue.Queue:
    """A queue the child's output lines arrive on, then None at its end (a daemon thread
    reads the pipe)."""
    lines: queue.Queue = queue.Queue(maxsize=10_000)

    def pump() -> None:
        for line in _lines(child.stdout):
            lines.put(line)
        lines.put(None)  # the end of its output

    threading.Thread(target=pump, daemon=True, name="trainer-child-output").start()
    return lines


def _lines(stream) -> Iterator[bytes]:
    """The stream's lines, each cut at :data:`MAX_LINE` bytes (a line without end cannot
    fill the trainer's memory)."""
    while True:
        line = stream.readline(MAX_LINE)
        if not line:
            return
        if not line.endswith(b"\n"):
            while True:
                rest = stream.readline(MAX_LINE)
                if not rest or rest.endswith(b"\n"):
                    break
        yield line


def job_file(folder: Path, *parts: str) -> Path | None:
    """``folder/parts...`` if it is a regular file really inside ``folder``, else None:
    the job wrote it, and a link it planted must not make the trainer read a host file."""
    path = folder.joinpath(*parts)
    try:
        inside = path.resolve(strict=True).is_relative_to(folder.resolve(strict=True))
    except (OSError, RuntimeError):
        return None
    return path if inside and path.is_file() else None


def race_poses(run_dir: Path, iteration: object) -> dict | None:
    """The poses of one race of a training iteration, for the live view: the longest
    episode of its training simtrace, at most :data:`MAX_POSES` steps (x, y, yaw rounded
    to mm and mrad, a few kB). The file is the job's own output, so anything odd in it
    gives None."""
    if not isinstance(iteration, int) or iteration < 0:
        return None
    path = job_file(run_dir, "0", "training-simtrace", f"{iteration}-iteration.csv")
    try:
        if path is None or path.stat().st_size > MAX_SIMTRACE_BYTES:
            return None
        episodes: dict[str, list[tuple[float, float, float]]] = {}
        with path.open(newline="") as handle:
            for row in csv.DictReader(handle):
                pose = (float(row["X"]), float(row["Y"]), float(row["yaw"]))
                episodes.setdefault(row["episode"], []).append(pose)
    except (OSError, KeyError, ValueError, TypeError, csv.Error):
        return None
    if not episodes:
        return None
    episode, poses = max(episodes.items(), key=lambda item: len(item[1]))
    poses = poses[:: max(1, -(-len(poses) // MAX_POSES))]
    return {
        "iteration": iteration,
        "episode": episode,
        "x": [round(p[0], 3) for p in poses],
        "y": [round(p[1], 3) for p in poses],
        "yaw": [round(p[2], 3) for p in poses],
    }


def _failure(code: int | None, watch: _Watch, settings: Settings) -> str | None:
    """Why the child failed, in a sentence, or None when it ended well."""
    if watch.why_killed is not None:
        return f"the job was stopped: {watch.why_killed}"
    tail = "\n".join(watch.tail[-8:])
    if any(word in tail for word in MEMORY_WORDS):
        return (
            f"the job ran out of memory (training_memory_mb: {settings.training_memory_mb} MiB "
            f"per process). Last output:\n{tail}"
        )
    if code == -signal.SIGXCPU:
        return "the job used up its CPU time"
    if code == -signal.SIGXFSZ or "File too large" in tail:
        return f"the job wrote a file over {settings.training_file_mb} MiB (training_file_mb)"
    if code != 0 or watch.done is None:
        how = f"signal {-code}" if code is not None and code < 0 else f"exit code {code}"
        return f"the training program ended with {how}. Last output:\n{tail}"
    return None


def main(argv: list[str] | None = None) -> None:
    """``python -m league.training.trainer``: one trainer (settings from the environment)."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    name = argv[0] if argv else None
    Trainer(Settings(), name).run_forever()


if __name__ == "__main__":
    main()
