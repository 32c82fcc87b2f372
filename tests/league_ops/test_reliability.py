"""Real worker processes against a real database: kill -9 and an unreachable database.

Races are short (1 lap of beginner_loop, a 20 s time limit) and leases 2 s, so a killed
worker's job comes back quickly. PostgreSQL's outage is real: workers reach the database
through a loopback TCP proxy that is stopped (every connection dropped) and restarted.
SQLite has no server to stop, so its outage is another process holding the write lock
(``BEGIN EXCLUSIVE``): every write fails with "database is locked" until it lets go.
"""

from __future__ import annotations

import contextlib
import random
import signal
import socket
import threading
import time
from collections import Counter, defaultdict

import pytest
from sqlalchemy import func, make_url, select

from arena.config import RaceConfig
from arena.race import run_race
from league import ranking
from league.jobs.evaluation import build_plan, policies
from league.jobs.scheduler import Scheduler
from league.models import Job, Race, Rating, utcnow
from tests.league_ops.conftest import Ops
from tests.league_ops.helpers import (
    all_settled,
    enter,
    event,
    model,
    racer,
    set_max_attempts,
    statuses,
    wait_until,
)


def _league(ops: Ops) -> None:
    """3 racers in a time trial (2 seeds each) and a head-to-model round (2 races)."""
    trial = event(ops, seeds=[0, 1])
    h2h = event(ops, race_type="head_to_model", round_interval_s=60, seeds=[0])
    for i, alias in enumerate(("ada", "bob", "cyd")):
        owner = racer(ops, alias)
        enter(ops, trial, model(ops, owner, seed=i))
        enter(ops, h2h, model(ops, owner, seed=10 + i))
    Scheduler(ops.settings).tick(utcnow())


def _check_exactly_once(ops: Ops) -> None:
    """One race per job, each reproducing a clean run; ratings applied once per race."""
    with ops.sessions() as session:
        jobs = session.scalars(select(Job)).all()
        races = session.scalars(select(Race).order_by(Race.id)).all()
        assert {j.status for j in jobs} == {"done"}
        assert sorted(r.job_id for r in races) == sorted(j.id for j in jobs)
        appearances: Counter[int] = Counter()
        skills: dict[int, ranking.Skill] = defaultdict(ranking.initial_skill)
        for race in races:
            job = session.get_one(Job, race.job_id)
            clean = run_race(
                RaceConfig.model_validate(race.config),
                policies(build_plan(session, ops.storage, job)),
                record_trace=False,
            )
            stored = {
                c.car_name: (c.finish_position, c.lap_times_ms, c.distance_m) for c in race.cars
            }
            fresh = {
                c.name: (c.finish_position, [round(t * 1000) for t in c.lap_times], c.distance)
                for c in clean.cars
            }
            assert stored == fresh
            rated = [c for c in race.cars if c.model_id is not None]
            if job.kind == "round":  # replay the ratings in commit order
                new = ranking.rate(
                    [skills[c.model_id] for c in rated], [c.finish_position for c in rated]
                )
                for car, skill in zip(rated, new, strict=True):
                    skills[car.model_id] = skill
                    appearances[car.model_id] += 1
        stored_ratings = session.scalars(select(Rating)).all()
        assert {r.model_id: r.races for r in stored_ratings} == dict(appearances)
        for row in stored_ratings:
            assert abs(row.mu - skills[row.model_id].mu) < 1e-9
        assert session.scalar(select(func.count(Race.id))) == len(jobs)


def test_kill_9_workers_mid_race_every_job_completes_exactly_once(ops: Ops) -> None:
    _league(ops)
    set_max_attempts(ops, 1000)
    rng = random.Random(7)
    workers = {i: ops.start("worker", f"worker{i}") for i in range(2)}
    kills, deadline = 0, time.monotonic() + 150
    while not all_settled(ops) and kills < 14 and time.monotonic() < deadline:
        # Kill while a race is under way (races are short: waiting blindly can miss them).
        while not statuses(ops).get("running") and not all_settled(ops):
            if time.monotonic() > deadline:
                pytest.fail(f"no job running or settled in 150 s: {statuses(ops)}")
            time.sleep(0.05)
        time.sleep(rng.uniform(0.0, 0.5))
        victim = rng.choice(list(workers))
        workers[victim].send_signal(signal.SIGKILL)
        workers[victim].wait()
        kills += 1
        workers[victim] = ops.start("worker", f"worker{victim}")
    wait_until(lambda: all_settled(ops), 120, "every job to finish")
    assert kills >= 3
    with ops.sessions() as session:
        assert session.scalar(select(func.max(Job.attempts))) > 1  # some job was cut short
    _check_exactly_once(ops)
    for proc in workers.values():
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0


class Proxy:
    """A loopback TCP proxy to the database that can be stopped (all links cut) and restarted."""

    def __init__(self, target: tuple[str, int]) -> None:
        self.target = target
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            self.port = probe.getsockname()[1]
        self.links: list[socket.socket] = []
        self.server: socket.socket | None = None

    def start(self) -> None:
        """Listen again on the same port."""
        server = socket.socket()
        server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        server.bind(("127.0.0.1", self.port))
        server.listen(64)
        self.server = server
        threading.Thread(target=self._accept, args=(server,), daemon=True).start()

    def stop(self) -> None:
        """Stop listening and cut every open connection, as a dying proxy would.

        ``shutdown`` before ``close``: closing a socket that a pipe thread is reading
        neither wakes that thread nor tells the peer, so a client waiting for a reply
        would wait forever and the server would keep its transaction open.
        """
        if self.server is not None:
            self.server.close()
            self.server = None
        links, self.links = self.links, []
        for link in links:
            with contextlib.suppress(OSError):
                link.shutdown(socket.SHUT_RDWR)
            link.close()

    def _accept(self, server: socket.socket) -> None:
        while True:
            try:
                client, _ = server.accept()
            except OSError:
                return
            upstream = socket.create_connection(self.target)
            self.links += [client, upstream]
            for a, b in ((client, upstream), (upstream, client)):
                threading.Thread(target=self._pipe, args=(a, b), daemon=True).start()

    @staticmethod
    def _pipe(source: socket.socket, sink: socket.socket) -> None:
        try:
            while data := source.recv(65536):
                sink.sendall(data)
        except OSError:
            pass
        finally:
            for sock in (source, sink):
                with contextlib.suppress(OSError):
                    sock.shutdown(socket.SHUT_RDWR)


def _outage(ops: Ops, seconds: float) -> dict[str, object]:
    """Make the database unreachable for ``seconds``; what the workers should use."""
    if ops.backend == "postgres":
        url = make_url(ops.url)
        proxy = Proxy((url.host or "127.0.0.1", url.port or 5432))
        proxy.start()
        ops.url = url.set(port=proxy.port).render_as_string(hide_password=False)
        return {"cut": proxy.stop, "heal": proxy.start}
    lock = ops.engine.connect()

    def cut() -> None:
        lock.exec_driver_sql("BEGIN EXCLUSIVE")

    def heal() -> None:
        lock.exec_driver_sql("COMMIT")
        lock.close()

    return {"cut": cut, "heal": heal, "extra": {"sqlite_busy_timeout_ms": 200}}


def test_database_outage_workers_and_scheduler_back_off_and_recover(ops: Ops) -> None:
    trial = event(ops, seeds=[0, 1, 2, 3])
    for i, alias in enumerate(("ada", "bob")):
        enter(ops, trial, model(ops, racer(ops, alias), seed=i))
    outage = _outage(ops, 4.0)
    extra = outage.get("extra", {})
    workers = [ops.start("worker", f"worker{i}", **extra) for i in range(2)]
    scheduler = ops.start("scheduler", "scheduler", **extra)
    wait_until(lambda: statuses(ops).get("done", 0) >= 1, 60, "a first result")
    outage["cut"]()
    time.sleep(4.0)
    outage["heal"]()
    wait_until(lambda: all_settled(ops), 90, "every job to finish after the outage")
    assert all(p.poll() is None for p in [*workers, scheduler]), "a process crashed"
    logs = "".join(ops.log(n) for n in ("worker0", "worker1", "scheduler"))
    assert "database unavailable" in logs
    assert statuses(ops) == {"done": 8}
    with ops.sessions() as session:
        assert session.scalar(select(func.count(Race.id))) == 8
    for proc in [*workers, scheduler]:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0
