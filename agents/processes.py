"""Helper processes of a training run (env workers, the evaluation process) and the stop
signals the trainer handles for them."""

from __future__ import annotations

import multiprocessing as mp
import signal
import threading
from collections.abc import Callable
from typing import Any

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""What stops training (Ctrl-C, ``kill`` / systemd / a container stop, a closed terminal):
the trainer handles them and closes its helpers, which ignore them; a helper whose trainer
is gone exits when its pipe closes."""


def ignore_stop_signals() -> None:
    """In a helper process: leave the stop signals to the trainer."""
    for sig in STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)


def spawn_helper(target: Callable[..., None], *args: Any) -> tuple[Any, Any]:
    """Start ``target(conn, *args)`` in a spawned daemon process; returns the trainer's end
    of the pipe and the process.

    The stop signals are ignored while it starts (inherited through exec, so a Ctrl-C to
    the process group while it imports cannot kill it); ``target`` should ignore them too
    (:func:`ignore_stop_signals`).
    """
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe()
    main = threading.current_thread() is threading.main_thread()
    previous = {s: signal.signal(s, signal.SIG_IGN) for s in STOP_SIGNALS} if main else None
    try:
        proc = ctx.Process(target=target, args=(child, *args), daemon=True)
        proc.start()
    finally:
        for sig, handler in (previous or {}).items():
            signal.signal(sig, handler)
    child.close()
    return parent, proc
