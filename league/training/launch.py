"""Start the child that runs a racer's training code: in the sandbox, or (only where the admin
opted in with ``training_unconfined``) under rlimits alone. Used by the API's reward check
and by trainers; the API process itself never runs a racer's code.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from pathlib import Path

from league.settings import Settings
from league.training.sandbox import (
    ConfinementLimits,
    SandboxUnavailable,
    confined_popen,
    kill_confined,
    limited,
    probe,
)

CHECK_MEMORY_MB = 2048
CHECK_CPU_SECONDS = 20


def limits_of(settings: Settings, cpu_seconds: int) -> ConfinementLimits:
    """The sandbox limits of a training child under ``settings``."""
    return ConfinementLimits(
        memory_mb=settings.training_memory_mb,
        cpu_seconds=cpu_seconds,
        processes=settings.training_processes,
        file_mb=settings.training_file_mb,
    )


def training_refused(settings: Settings) -> str | None:
    """Why this host must refuse training jobs, or None when it may run them."""
    reason = probe()
    if reason is None or settings.training_unconfined:
        return None
    return (
        f"Training is off on this server: it cannot sandbox racers' reward functions "
        f"({reason}). The admin can install bubblewrap, or set "
        "SLIPSTREAM_TRAINING_UNCONFINED=true for a league of trusted racers (docs/deploy.md)."
    )


def start_child(
    args: list[str],
    workdir: Path,
    settings: Settings,
    limits: ConfinementLimits,
    module: str = "agents.train_job",
) -> subprocess.Popen[bytes]:
    """``python -m MODULE WORKDIR *args`` (by default ``agents.train_job``) as a child,
    sandboxed unless the host cannot and the admin opted in; stdout and stderr merged into
    one pipe."""
    argv = [sys.executable, "-m", module, str(workdir), *args]
    if probe() is None:
        return confined_popen(argv, workdir, limits)
    if not settings.training_unconfined:
        raise SandboxUnavailable(training_refused(settings) or "no sandbox")
    return subprocess.Popen(
        limited(argv, limits),
        cwd=workdir,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )


def stop_child(proc: subprocess.Popen[bytes]) -> None:
    """Kill the child and everything it started: the sandbox, or (unconfined) the
    child's process group."""
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(proc.pid, signal.SIGKILL)  # bwrap's own group, or the whole child
    kill_confined(proc)
