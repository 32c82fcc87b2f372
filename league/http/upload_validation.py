"""Validate uploads outside the API process: one child per upload, under limits, a few at once.

The upload route awaits a fresh ``python -m league.http.upload_validation`` child (never a
fork of the threaded server). The child puts itself under
:func:`league.jobs.sandbox.limit_self` (address space: a race's memory allowance,
``race_memory_mb``; CPU: ``validation_cpu_seconds``), reads the archive from stdin, runs
:func:`submissions.validate` and writes its report as JSON to stdout; the parent kills it
at ``validation_wall_seconds``. Every way the child can fail
becomes a :class:`~submissions.Problem`, so the API process never parses the graph nor
builds an onnxruntime session, and its memory stays flat. :class:`UploadValidator` lets
``validation_concurrency`` children run at once and ``validation_queue`` uploads wait (at
most ``validation_wait_seconds``); beyond that it raises :class:`ValidationBusy` (503).
The slots are shared per racer: one racer may have ``validation_per_racer`` uploads being
validated or waiting, so a burst of one racer's uploads leaves room for everyone else's.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from pydantic import ValidationError

from league.jobs.sandbox import SandboxLimits, limit_self, one_thread_env
from league.settings import Settings
from submissions import Limits, Problem, ValidationReport, validate
from submissions.format import MEMORY_WORDS

RETRY_AFTER_SECONDS = 5
MAX_REPORT_BYTES = 4 * 1024 * 1024


class ValidationBusy(RuntimeError):
    """Every validation slot is taken and the line is full (or the wait ran out)."""


def _refused(expected: str, found: str, message: str) -> ValidationReport:
    problem = Problem(field="policy.onnx:run", expected=expected, found=found, message=message)
    return ValidationReport(problems=(problem,))


class RacerUploadLimit(ValidationBusy):
    """This racer already has as many uploads validating or waiting as one racer may (429)."""


class UploadValidator:
    """Runs validation children for the API: bounded in number, each under limits."""

    def __init__(self, settings: Settings) -> None:
        self.limits = SandboxLimits(
            memory_mb=settings.race_memory_mb,
            cpu_seconds=settings.validation_cpu_seconds,
            wall_seconds=settings.validation_wall_seconds,
            max_output_bytes=MAX_REPORT_BYTES,
        )
        self.max_archive_bytes = settings.max_upload_bytes
        self._slots = asyncio.Semaphore(settings.validation_concurrency)
        self._line = settings.validation_queue
        self._wait_seconds = settings.validation_wait_seconds
        self._waiting = 0
        self._per_racer = settings.validation_per_racer
        self._racer_running = max(1, settings.validation_concurrency - 1)
        self._racers: dict[int, tuple[int, asyncio.Semaphore]] = {}

    @asynccontextmanager
    async def slot(self, racer_id: int | None = None) -> AsyncIterator[None]:
        """Hold one validation slot, waiting in line if there is room; else ValidationBusy.

        With ``racer_id`` the slots are shared per racer: a racer may have
        ``validation_per_racer`` uploads holding or waiting for a slot (past that the upload
        is refused at once) and hold all but one slot (when there are several), so another
        racer's upload always finds a slot within one validation."""
        if racer_id is None:
            async with self._held(None):
                yield
            return
        count, own = self._racers.get(racer_id, (0, asyncio.Semaphore(self._racer_running)))
        if count >= self._per_racer:
            raise RacerUploadLimit(
                f"You have {count} uploads being validated or waiting, the most one racer "
                "may have; send the next one when one of them is done."
            )
        self._racers[racer_id] = (count + 1, own)
        try:
            async with self._held(own):
                yield
        finally:
            count, own = self._racers[racer_id]
            if count > 1:
                self._racers[racer_id] = (count - 1, own)
            else:
                del self._racers[racer_id]

    @asynccontextmanager
    async def _held(self, own: asyncio.Semaphore | None) -> AsyncIterator[None]:
        """Take the racer's own slot (``own``) then a shared one, waiting in line at most
        ``validation_wait_seconds`` in all; ValidationBusy when the line is full."""
        if self._slots.locked() and self._waiting >= self._line:
            raise ValidationBusy("Every validation slot is busy and the line is full.")
        self._waiting += 1
        taken: list[asyncio.Semaphore] = []
        try:
            async with asyncio.timeout(self._wait_seconds):
                for semaphore in (own, self._slots):
                    if semaphore is not None:
                        await semaphore.acquire()
                        taken.append(semaphore)
        except BaseException as exc:  # timed out, or the client left while waiting
            for semaphore in taken:
                semaphore.release()
            if isinstance(exc, TimeoutError):
                raise ValidationBusy(
                    f"No validation slot came free within {self._wait_seconds:g} s."
                ) from None
            raise
        finally:
            self._waiting -= 1
        try:
            yield
        finally:
            for semaphore in taken:
                semaphore.release()

    async def validate(self, data: bytes) -> ValidationReport:
        """The report on ``data`` from a child under the limits (hold a :meth:`slot`)."""
        limits = self.limits
        arguments = {
            "memory_mb": limits.memory_mb,
            "cpu_seconds": limits.cpu_seconds,
            "max_archive_bytes": self.max_archive_bytes,
        }
        child = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "league.http.upload_validation", json.dumps(arguments),
            stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
            env=one_thread_env(),
        )  # fmt: skip
        try:
            async with asyncio.timeout(limits.wall_seconds):
                out, _ = await child.communicate(data)
        except TimeoutError:
            return _refused(
                f"validation within {limits.wall_seconds:g} s",
                "still running; stopped",
                "Validating the model took too long (building or running the policy).",
            )
        finally:
            if child.returncode is None:
                child.kill()
                await child.wait()
        return self._verdict(child.returncode, out)

    def _verdict(self, code: int | None, out: bytes) -> ValidationReport:
        limits = self.limits
        if code == -signal.SIGXCPU:
            return _refused(
                f"validation within {limits.cpu_seconds} s of CPU time",
                "the limit was reached; stopped",
                "Validating the model took too much CPU (building or running the policy).",
            )
        if code != 0 or len(out) > limits.max_output_bytes:
            how = f"signal {-code}" if code is not None and code < 0 else f"exit code {code}"
            return _refused(
                f"validation within {limits.cpu_seconds} s of CPU time "
                f"and {limits.memory_mb} MiB of memory",
                f"the validation process ended with {how}",
                "Validating the model failed: it ran out of memory or CPU time, or crashed.",
            )
        try:
            return ValidationReport.model_validate_json(out)
        except ValidationError:
            return _refused("a validation report", "an unreadable answer", "Validation failed.")


def _with_memory_verdict(report: ValidationReport, memory_mb: int) -> ValidationReport:
    """The report, with allocation failures said as the memory limit they hit."""
    problems = tuple(
        Problem(
            field=p.field,
            expected=f"at most {memory_mb} MiB to load and run (a race's allowance)",
            found=p.found,
            message="The policy needs more memory than a race allows.",
        )
        if any(word in p.found for word in MEMORY_WORDS)
        else p
        for p in report.problems
    )
    return report.model_copy(update={"problems": problems})


def main() -> None:
    """Child side: limits on, read the archive from stdin, write the report to stdout."""
    arguments = json.loads(sys.argv[1])
    memory_mb = arguments["memory_mb"]
    limit_self(SandboxLimits(memory_mb=memory_mb, cpu_seconds=arguments["cpu_seconds"]))
    limits = Limits(max_archive_bytes=arguments["max_archive_bytes"])
    data = sys.stdin.buffer.read(limits.max_archive_bytes + 1)
    report = _with_memory_verdict(validate(data, limits), memory_mb)
    sys.stdout.write(report.model_dump_json())
    sys.stdout.flush()
    os._exit(0)  # skip onnxruntime's teardown


if __name__ == "__main__":
    main()
