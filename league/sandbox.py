"""Run untrusted work (a race with submitted models) in a child process under hard limits.

The worker forks a child per race (the worker is single-threaded, so forking is safe and
the child starts with the arena already imported). The child sets ``RLIMIT_AS`` (its
address space at fork plus the memory allowance), ``RLIMIT_CPU`` and asks to be killed if
the worker dies; the parent enforces the wall-clock limit with SIGKILL. The child's answer
comes back as JSON over a pipe (never pickle), capped in size. Any way the child can fail
becomes a :class:`SandboxError` whose message says which limit was hit.
:func:`limit_self` is the limits part alone, also used by the upload validation child
(:mod:`league.validation`).
"""

from __future__ import annotations

import contextlib
import ctypes
import faulthandler
import json
import os
import resource
import select
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from submissions.format import MEMORY_WORDS

MiB = 1024 * 1024
ONE_THREAD = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
"""Variables that hold BLAS and OpenMP libraries to one thread in a child process."""
_PR_SET_PDEATHSIG = 1



def one_thread_env() -> dict[str, str]:
    """This process's environment with every :data:`ONE_THREAD` variable set to 1."""
    return {**os.environ, **dict.fromkeys(ONE_THREAD, "1")}


@dataclass(frozen=True)
class SandboxLimits:
    """What one child may use: extra address space, CPU seconds, wall seconds, answer size."""

    memory_mb: int = 1024
    cpu_seconds: int = 600
    wall_seconds: float = 900.0
    max_output_bytes: int = 256 * MiB


class SandboxError(RuntimeError):
    """The child failed: ``kind`` is ``wall``, ``cpu``, ``memory``, ``crash`` or ``error``."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


def _address_space() -> int:
    with open("/proc/self/statm") as handle:
        return int(handle.read().split()[0]) * resource.getpagesize()


def _die_with_parent() -> None:
    with contextlib.suppress(OSError, AttributeError):  # not Linux: other limits still apply
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)


def limit_self(limits: SandboxLimits) -> None:
    """Put this process under ``limits``: killed if its parent dies, one BLAS thread,
    ``RLIMIT_AS`` its address space now plus ``memory_mb``, ``RLIMIT_CPU`` the CPU time it
    has used so far plus ``cpu_seconds``."""
    faulthandler.disable()  # a crash is reported by the parent, not as a stack dump
    _die_with_parent()
    for name in ONE_THREAD:
        os.environ[name] = "1"
    cap = _address_space() + limits.memory_mb * MiB
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    usage = resource.getrusage(resource.RUSAGE_SELF)
    cpu = int(usage.ru_utime + usage.ru_stime) + limits.cpu_seconds
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 2))


def _child(target: Callable[[], Any], fd: int, limits: SandboxLimits) -> None:
    """Child side: limits on, run ``target``, write ``{"ok": ...}`` or ``{"error": ...}``."""
    try:
        limit_self(limits)
        payload: dict[str, Any] = {"ok": target()}
    except BaseException as exc:  # everything becomes an answer
        text = f"{type(exc).__name__}: {exc}"
        memory = isinstance(exc, MemoryError) or any(w in text for w in MEMORY_WORDS)
        payload = {"error": "memory" if memory else "error", "message": text[:2000]}
    try:
        data = json.dumps(payload, separators=(",", ":")).encode()
    except (TypeError, ValueError, MemoryError) as exc:
        data = json.dumps({"error": "error", "message": f"unserialisable answer: {exc}"}).encode()
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
    finally:
        os._exit(0)


def _read(fd: int, pid: int, limits: SandboxLimits, tick: Callable[[], None] | None) -> bytes:
    """Collect the child's answer until EOF; SIGKILL it on the wall limit or a tick error."""
    deadline = time.monotonic() + limits.wall_seconds
    chunks, size = [], 0
    try:
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise SandboxError(
                    "wall", f"the race exceeded its wall-time limit of {limits.wall_seconds:g} s"
                )
            ready, _, _ = select.select([fd], [], [], min(left, 1.0))
            if tick is not None:
                tick()
            if not ready:
                continue
            chunk = os.read(fd, 1 << 20)
            if not chunk:
                return b"".join(chunks)
            size += len(chunk)
            if size > limits.max_output_bytes:
                raise SandboxError("error", "the race answer exceeded the output size limit")
            chunks.append(chunk)
    except BaseException:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        raise


def _verdict(status: int, data: bytes, limits: SandboxLimits) -> Any:
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        if sig == signal.SIGXCPU:
            raise SandboxError(
                "cpu", f"the race exceeded its CPU-time limit of {limits.cpu_seconds} s"
            )
        if sig == signal.SIGKILL:
            raise SandboxError(
                "cpu",
                f"the race process was killed (CPU-time limit of {limits.cpu_seconds} s "
                "reached, or the system ran out of memory)",
            )
        name = signal.Signals(sig).name
        raise SandboxError(
            "crash",
            f"the race process was killed by {name} (memory limit {limits.memory_mb} MiB)",
        )
    if not data:
        code = os.WEXITSTATUS(status)
        raise SandboxError("crash", f"the race process exited with code {code} and no answer")
    answer = json.loads(data)
    if "ok" in answer:
        return answer["ok"]
    if answer.get("error") == "memory":
        raise SandboxError(
            "memory",
            f"the race exceeded its memory limit of {limits.memory_mb} MiB "
            f"({answer.get('message', '')})",
        )
    raise SandboxError("error", str(answer.get("message", "unknown error")))


def run_limited(
    target: Callable[[], Any], limits: SandboxLimits, tick: Callable[[], None] | None = None
) -> Any:
    """Run ``target()`` in a forked child under ``limits``; return its JSON-decoded answer.

    ``tick()`` runs in the parent about once a second while waiting (heartbeats); if it
    raises, the child is killed and the exception propagates. Raises :class:`SandboxError`.
    """
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child never returns
        os.close(read_fd)
        _child(target, write_fd, limits)
    os.close(write_fd)
    try:
        data = _read(read_fd, pid, limits, tick)
    finally:
        os.close(read_fd)
    _, status = os.waitpid(pid, 0)
    return _verdict(status, data, limits)
