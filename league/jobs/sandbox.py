"""Run untrusted work (a race with submitted models) in a child process under hard limits.

Two ways, with the same limits and the same errors. :func:`run_limited` forks a child for
one ``target()``. :class:`WarmSandbox` keeps a forked child between requests: the worker
sends it a request (bytes) over a pipe, it answers and waits for the next one, and it is
replaced after ``max_runs`` requests, after any request that did not answer ``ok`` and
once its address space has grown ``high_water_mb`` past its size at fork. Either child
starts with the arena already imported (it is forked from a single-threaded worker), sets
``RLIMIT_AS`` (its address space when the work starts plus the memory allowance) and
``RLIMIT_CPU`` (CPU time used so far plus the allowance) and asks to be killed if the
worker dies; the parent enforces the wall-clock limit with SIGKILL. Answers come back as
JSON over a pipe (never pickle), capped in size. Any way the child can fail becomes a
:class:`SandboxError` whose message says which limit was hit. :func:`limit_self` is the
limits part alone, also used by the upload validation child
(:mod:`league.http.upload_validation`).
"""

from __future__ import annotations

import contextlib
import ctypes
import faulthandler
import gc
import json
import math
import os
import resource
import select
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NoReturn

from submissions.format import MEMORY_WORDS

MiB = 1024 * 1024
ONE_THREAD = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
"""Variables that hold BLAS and OpenMP libraries to one thread in a child process."""
_PR_SET_PDEATHSIG = 1
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_PARENT_FDS: set[int] = set()
"""This process's ends of its warm children's pipes; every forked child closes them, so a
child's death always reaches its parent as end-of-file."""


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


def _cpu_used() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _die_with_parent() -> None:
    with contextlib.suppress(OSError, AttributeError):  # not Linux: other limits still apply
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)


def _child_setup() -> None:
    """First steps of any sandbox child: no stack dumps, die with the parent, one thread."""
    for fd in _PARENT_FDS:
        with contextlib.suppress(OSError):
            os.close(fd)
    faulthandler.disable()  # a crash is reported by the parent, not as a stack dump
    _die_with_parent()
    for name in ONE_THREAD:
        os.environ[name] = "1"


def limit_self(limits: SandboxLimits) -> None:
    """Put this process under ``limits``: killed if its parent dies, one BLAS thread,
    ``RLIMIT_AS`` its address space now plus ``memory_mb``, ``RLIMIT_CPU`` the CPU time it
    has used so far plus ``cpu_seconds``."""
    _child_setup()
    cap = _address_space() + limits.memory_mb * MiB
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    cpu = int(_cpu_used()) + limits.cpu_seconds
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 2))


def _payload(target: Callable[[], Any], before: Callable[[], None]) -> dict[str, Any]:
    """``{"ok": target()}`` after ``before()``, or ``{"error": kind, "message": ...}``."""
    try:
        before()
        return {"ok": target()}
    except BaseException as exc:  # everything becomes an answer
        text = f"{type(exc).__name__}: {exc}"
        memory = isinstance(exc, MemoryError) or any(w in text for w in MEMORY_WORDS)
        return {"error": "memory" if memory else "error", "message": text[:2000]}


def _encode(payload: dict[str, Any]) -> bytes:
    try:
        return json.dumps(payload, separators=(",", ":")).encode()
    except (TypeError, ValueError, MemoryError) as exc:
        return json.dumps({"error": "error", "message": f"unserialisable answer: {exc}"}).encode()


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


def _child(target: Callable[[], Any], fd: int, limits: SandboxLimits) -> NoReturn:
    """Child side of :func:`run_limited`: limits on, run ``target``, write the answer, exit."""
    try:
        _write_all(fd, _encode(_payload(target, lambda: limit_self(limits))))
    finally:
        os._exit(0)


def _read(
    fd: int, pid: int, limits: SandboxLimits, tick: Callable[[], None] | None, framed: bool
) -> bytes | None:
    """Collect the child's answer: until EOF, or with ``framed`` one length-prefixed frame
    (None if EOF comes first). SIGKILL and reap the child on the wall limit, an oversized
    answer or a tick error."""
    deadline = time.monotonic() + limits.wall_seconds
    buffer = bytearray()
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
                return None if framed else bytes(buffer)
            buffer += chunk
            size = int.from_bytes(buffer[:8], "big") if framed else len(buffer)
            if size > limits.max_output_bytes:
                raise SandboxError("error", "the race answer exceeded the output size limit")
            if framed and len(buffer) >= 8 + size:
                return bytes(buffer[8 : 8 + size])
    except BaseException:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        raise


def _verdict(status: int, data: bytes, limits: SandboxLimits) -> Any:
    """The answer of a child that exited with ``status`` after writing ``data``."""
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
    return _decode(json.loads(data), limits)


def _decode(answer: dict[str, Any], limits: SandboxLimits) -> Any:
    """The ``ok`` value of an answer, or its error as a :class:`SandboxError`."""
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
        data = _read(read_fd, pid, limits, tick, framed=False)
    finally:
        os.close(read_fd)
    _, status = os.waitpid(pid, 0)
    return _verdict(status, data or b"", limits)


def _keep_freed_memory() -> None:
    """Let glibc keep freed memory for the next request (a physics world is tens of MiB that
    would otherwise be unmapped and page-faulted in again every race)."""
    with contextlib.suppress(OSError, AttributeError):  # not glibc: only slower
        libc = ctypes.CDLL(None)
        libc.mallopt(_M_MMAP_THRESHOLD, 32 * MiB)
        libc.mallopt(_M_TRIM_THRESHOLD, 1024 * MiB)


def _receive(fd: int) -> bytes | None:
    """One length-prefixed frame from ``fd``; None at end of file."""
    data = bytearray()
    need = 8
    while len(data) < need:
        chunk = os.read(fd, min(need - len(data), 1 << 20))
        if not chunk:
            return None
        data += chunk
        if need == 8 and len(data) == 8:
            need += int.from_bytes(data, "big")
    return bytes(data[8:])


def _frame(data: bytes) -> bytes:
    return len(data).to_bytes(8, "big") + data


class WarmSandbox:
    """A forked child kept between requests; each request runs under ``limits`` of its own.

    ``handler(request)`` runs in the child and returns a JSON-ready answer. For each request
    the child sets soft ``RLIMIT_AS`` to its address space at that moment plus
    ``memory_mb`` and soft ``RLIMIT_CPU`` to the CPU time it has used (rounded up) plus
    ``cpu_seconds`` (the hard limits, set at fork, are lifetime ceilings); the parent SIGKILLs
    it at ``wall_seconds``. The errors are :func:`run_limited`'s. The child is replaced
    after ``max_runs`` requests, after any request that did not answer ``ok`` (or killed
    it) and once its address space is ``high_water_mb`` past its size at fork.
    """

    def __init__(
        self,
        handler: Callable[[bytes], Any],
        limits: SandboxLimits,
        *,
        max_runs: int = 50,
        high_water_mb: int = 256,
    ) -> None:
        self.handler = handler
        self.limits = limits
        self.max_runs = max_runs
        self.high_water_mb = high_water_mb
        self.pid: int | None = None
        self.runs = 0
        self.forks = 0
        self._fds = (-1, -1)
        self._born_size = 0
        self._owner = os.getpid()

    def run(self, request: bytes, tick: Callable[[], None] | None = None) -> Any:
        """Answer ``request`` in the warm child (forked first if there is none, or if it
        died while idle). ``tick()`` is :func:`run_limited`'s. Raises :class:`SandboxError`."""
        if self.pid is not None and os.waitpid(self.pid, os.WNOHANG)[0]:
            self._forget()  # killed while idle (say by the OOM killer): not this race's fault
        if self.pid is None:
            self._spawn()
        assert self.pid is not None
        pid, (to_child, from_child) = self.pid, self._fds
        try:
            _write_all(to_child, _frame(request))
        except BrokenPipeError:
            pass  # it died: its exit status below says how
        except BaseException:
            self.close()
            raise
        try:
            data = _read(from_child, pid, self.limits, tick, framed=True)
        except BaseException:
            self._forget()  # _read killed and reaped it
            raise
        if data is None:
            _, status = os.waitpid(pid, 0)
            self._forget()
            return _verdict(status, b"", self.limits)
        self.runs += 1
        answer = json.loads(data)
        if "ok" not in answer or self.runs >= self.max_runs or self._grown():
            self.close()
        return _decode(answer, self.limits)

    def close(self) -> None:
        """Kill the child (if any); the next request forks a new one."""
        if os.getpid() != self._owner:  # a copy inherited by some child: not ours to close
            return
        if self.pid is not None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signal.SIGKILL)
            os.waitpid(self.pid, 0)
        self._forget()

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.close()

    def _forget(self) -> None:
        for fd in self._fds:
            if fd >= 0:
                _PARENT_FDS.discard(fd)
                os.close(fd)
        self.pid, self.runs, self._fds = None, 0, (-1, -1)

    def _grown(self) -> bool:
        try:
            with open(f"/proc/{self.pid}/statm") as handle:
                size = int(handle.read().split()[0]) * resource.getpagesize()
        except (OSError, ValueError):  # not Linux: max_runs alone retires children
            return False
        return size > self._born_size + self.high_water_mb * MiB

    def _spawn(self) -> None:
        request_r, request_w = os.pipe()
        answer_r, answer_w = os.pipe()
        _PARENT_FDS.update((request_w, answer_r))
        self._born_size = _address_space()
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child never returns
            ceilings = (
                self._born_size + (self.high_water_mb + 2 * self.limits.memory_mb) * MiB,
                self.max_runs * (self.limits.cpu_seconds + 2) + 60,
            )
            _serve(self.handler, request_r, answer_w, self.limits, ceilings)
        os.close(request_r)
        os.close(answer_w)
        self.pid, self.runs, self._fds = pid, 0, (request_w, answer_r)
        self.forks += 1


def _serve(
    handler: Callable[[bytes], Any],
    request_fd: int,
    answer_fd: int,
    limits: SandboxLimits,
    ceilings: tuple[int, int],
) -> NoReturn:
    """Warm child: answer frames from ``request_fd`` until end of file, each under ``limits``.

    ``ceilings`` are the hard address space (bytes) and CPU seconds of its whole life.
    """
    memory_cap, cpu_cap = ceilings

    def limit_run() -> None:
        cap = min(_address_space() + limits.memory_mb * MiB, memory_cap)
        resource.setrlimit(resource.RLIMIT_AS, (cap, memory_cap))
        cpu = min(math.ceil(_cpu_used()) + limits.cpu_seconds, cpu_cap)
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu_cap))

    try:
        _child_setup()
        _keep_freed_memory()
        gc.freeze()  # the worker's objects: never collected here, so never copied for it
        resource.setrlimit(resource.RLIMIT_AS, (memory_cap, memory_cap))
        resource.setrlimit(resource.RLIMIT_CPU, (cpu_cap, cpu_cap))
        while (request := _receive(request_fd)) is not None:
            answer = _encode(_payload(lambda: handler(request), limit_run))
            _write_all(answer_fd, _frame(answer))
            resource.setrlimit(resource.RLIMIT_AS, (memory_cap, memory_cap))
            del request, answer
            gc.collect()
    finally:
        os._exit(0)
