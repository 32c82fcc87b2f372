"""Builders for the reliability tests: racers, models, events, entries, waiting."""

from __future__ import annotations

import time
from collections.abc import Callable
from datetime import timedelta
from typing import Any

from sqlalchemy import func, select, update

from arena.actions import default_discrete_space
from league import crud
from league.models import Entry, Event, Job, Model, Racer, utcnow
from league.schemas import EventCreate
from submissions import pack, validate
from tests.league.conftest import CREATED_AT, policy_onnx
from tests.league_ops.conftest import Ops


def racer(ops: Ops, alias: str) -> Racer:
    """A new racer."""
    with ops.sessions() as session:
        return crud.create_racer(session, alias)[0]


def model(ops: Ops, owner: Racer, onnx: bytes | None = None, seed: int = 0) -> Model:
    """Store a lidar model (``onnx`` graph, else the tiny MLP for ``seed``)."""
    path = ops.data_dir / f"upload-{owner.alias}-{seed}.zip"
    graph = onnx if onnx is not None else policy_onnx(seed)
    pack(path, graph, default_discrete_space(), ["lidar"], created_at=CREATED_AT)
    data = path.read_bytes()
    report = validate(data)
    assert report.ok, report.problems
    with ops.sessions() as session:
        return crud.add_model(session, ops.storage, owner, f"m{seed}", data, report.info)[0]


def event(ops: Ops, **fields: Any) -> Event:
    """A short event: 1 lap of beginner_loop, 20 s time limit, opened a minute ago."""
    spec = {"name": "Ops Cup", "laps": 1, "time_limit_s": 20.0, "seeds": [0, 1]}
    spec["opens_at"] = utcnow() - timedelta(minutes=1)
    with ops.sessions() as session:
        return crud.create_event(session, EventCreate(**{**spec, **fields}), None)


def enter(ops: Ops, ev: Event, md: Model) -> Entry:
    """Enter a model (evaluation events queue their jobs here)."""
    with ops.sessions() as session:
        return crud.enter_model(session, ev, md, utcnow())[0]


def set_max_attempts(ops: Ops, attempts: int) -> None:
    """Let every job survive ``attempts`` leases (kill tests kill many)."""
    with ops.sessions() as session:
        session.execute(update(Job).values(max_attempts=attempts))
        session.commit()


def statuses(ops: Ops) -> dict[str, int]:
    """Job count per status."""
    with ops.sessions() as session:
        rows = session.execute(select(Job.status, func.count(Job.id)).group_by(Job.status))
        return dict(rows.all())


def wait_until(check: Callable[[], bool], timeout: float, what: str) -> None:
    """Poll ``check`` every 0.2 s; fail the test after ``timeout`` seconds."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if check():
            return
        time.sleep(0.2)
    raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")


def all_settled(ops: Ops) -> bool:
    """No job is queued or running."""
    counts = statuses(ops)
    return counts.get("queued", 0) == 0 and counts.get("running", 0) == 0
