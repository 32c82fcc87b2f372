"""What every leasing daemon (an evaluation worker, a trainer) shares: its database and
file store, a loop that works until a stop signal and backs off while the database is
unreachable, and database calls retried until the database answers."""

from __future__ import annotations

import logging
import os
import signal
import socket
from collections.abc import Callable
from typing import Any

from league.db import make_engine, make_session_factory
from league.jobs.queue import DB_ERRORS, Backoff, sleep_unless_stopped
from league.settings import Settings
from league.store import open_storage


class LeasingDaemon:
    """A process that leases work from the database: subclasses define :meth:`run_once`."""

    kind = "daemon"
    """Its name in logs (``slipstream.KIND``) and in the start and stop lines."""

    def __init__(self, settings: Settings, name: str | None = None) -> None:
        self.settings = settings
        self.name = name or f"{socket.gethostname()}-{os.getpid()}"
        self.engine = make_engine(settings.db_url, settings.sqlite_busy_timeout_ms)
        self.sessions = make_session_factory(self.engine)
        self.storage = open_storage(settings)
        self.stopping = False
        self.backoff = Backoff()
        self.log = logging.getLogger(f"slipstream.{self.kind}")

    def run_once(self) -> bool:
        """Lease and process one piece of work; False when there was none."""
        raise NotImplementedError

    def stop(self, *_args: object) -> None:
        """Finish (or give back) the current work, then leave the loop (signal handler)."""
        self.stopping = True

    def run_forever(self) -> None:
        """Work until stopped; back off while the database is unreachable."""
        for stop_signal in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
            signal.signal(stop_signal, self.stop)
        self.log.info("%s %s started", self.kind, self.name)
        while not self.stopping:
            try:
                busy = self.run_once()
                self.backoff.reset()
            except DB_ERRORS as exc:
                self._wait_db(exc)
                continue
            if not busy:
                self._sleep(self.settings.poll_seconds)
        self.close()
        self.log.info("%s %s stopped", self.kind, self.name)

    def close(self) -> None:
        """Release what the daemon holds (after the loop)."""
        self.engine.dispose()

    def _retry_db(self, action: Callable[[Any], Any]) -> Any:
        """Run ``action(session)`` until the database answers (or the daemon must stop)."""
        while True:
            try:
                with self.sessions() as session:
                    return action(session)
            except DB_ERRORS as exc:
                self._wait_db(exc)

    def _wait_db(self, exc: Exception) -> None:
        delay = self.backoff.next()
        self.log.warning("database unavailable (%s); retrying in %.1f s", type(exc).__name__, delay)
        self._sleep(delay)

    def _sleep(self, seconds: float) -> None:
        sleep_unless_stopped(seconds, lambda: self.stopping)
