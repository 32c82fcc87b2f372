"""Holding a Ctrl-C (SIGINT) until a block that must not be cut in half has run."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def sigint_deferred() -> Iterator[None]:
    """Hold a Ctrl-C (SIGINT) that arrives in the block until the block has run, then
    hand it to the handler that was in place (Python's raises KeyboardInterrupt).

    Blocks nest: an inner block hands a held Ctrl-C to the outer one. Off the main thread
    (where no signal handler can be set) the block runs as it is.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught and callable(previous):
        previous(signal.SIGINT, None)
