"""What a job races: the config from the event's frozen ruleset, its cars and its seed.

A :class:`RacePlan` is plain data (the config, and per car either a model file's bytes or a
bot name), built in the worker from the database and sent to the sandboxed child as bytes
(:func:`encode_plan`, never pickle); :func:`policies` turns it into drivers inside the
child, loading submitted models only through ``submissions.load_policy``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from sqlalchemy.orm import Session

from arena.config import CarConfig, RaceConfig, resolve_track
from arena.policy import Policy
from arena.race import StepGuard
from league.bots import BOT_LEVELS, bot_car, bot_driver
from league.models import Entry, Event, Job, Model
from league.store.base import DigestMismatch, FileStore


@dataclass(frozen=True)
class CarPlan:
    """One car of a planned race: a submitted model (``model`` bytes) or a built-in bot."""

    name: str
    entry_id: int | None
    model: bytes | None = None
    bot: str | None = None


@dataclass(frozen=True)
class RacePlan:
    """Everything needed to run one job's race, and nothing from the database.

    ``step_budget_ms`` and ``step_window`` are the submitted models' per-step CPU budget
    (:class:`arena.race.StepGuard`); ``None``: no budget.
    """

    config: RaceConfig
    cars: tuple[CarPlan, ...]
    step_budget_ms: float | None = None
    step_window: int = 10

    def guard(self) -> StepGuard:
        """What takes a submitted model out of this race (DNF) rather than ending it: an
        output that is NaN or inf or of the wrong shape, an onnxruntime error, or steps over
        the budget. Bots are not guarded."""
        from submissions import ModelFault

        return StepGuard(
            faults=(ModelFault,),
            budget_ms=self.step_budget_ms,
            window=self.step_window,
            cars=frozenset(c.name for c in self.cars if c.model is not None),
        )


def car_name(slot: dict[str, Any], index: int) -> str:
    """The car name of a lineup slot: ``entry<ID>`` for models, ``bot<N>`` for bots."""
    return f"entry{slot['entry_id']}" if "entry_id" in slot else f"bot{index}"


def model_car(name: str, info: dict[str, Any]) -> CarConfig:
    """A car with the sensors, action space, lidar config and stack size a model declares."""
    fields: dict[str, Any] = {"name": name, "sensors": tuple(info["sensors"])}
    fields["action_space"] = info["action_space"]
    fields["stack_size"] = info.get("stack_size", 1)  # absent from models stored before it
    if info.get("lidar_config"):
        fields["lidar_config"] = info["lidar_config"]
    return CarConfig.model_validate(fields)


def lineup(job: Job) -> list[dict[str, Any]]:
    """The job's grid: its one entry (evaluations) or the stored round lineup."""
    if job.kind == "evaluation":
        return [{"entry_id": job.entry_id}]
    return list(job.lineup or [])


def checked_model_bytes(storage: FileStore, model: Model) -> bytes:
    """A model's stored archive, refused if it no longer matches the sha256 it was stored as.

    The bytes checked are the bytes raced: the plan carries them into the sandbox.
    """
    try:
        return storage.read("models", model.sha256)
    except DigestMismatch:
        raise DigestMismatch(
            f"stored model file {model.id} does not match its sha256; refusing to race it"
        ) from None


class EntrySuspended(ValueError):
    """An evaluation job's entry was suspended from its event: the job is not raced."""


def build_plan(
    session: Session,
    storage: FileStore,
    job: Job,
    *,
    step_budget_ms: float | None = None,
    step_window: int = 10,
) -> RacePlan:
    """The race for ``job``: event ruleset + cars (models' declared sensors) + job seed.

    Entries suspended from the event (:mod:`league.jobs.faults`) leave a round's grid (a
    bot fills it back to two cars, as matchmaking does for a lone model); an evaluation job
    of a suspended entry raises :class:`EntrySuspended`.
    """
    event = session.get_one(Event, job.event_id)
    cars, plans = [], []
    for index, slot in enumerate(lineup(job)):
        name = car_name(slot, index)
        if "entry_id" in slot:
            entry = session.get_one(Entry, slot["entry_id"])
            if entry.suspended_at is not None:
                if job.kind == "evaluation":
                    raise EntrySuspended(f"entry {entry.id} is suspended: {entry.suspension}")
                continue
            model = session.get_one(Model, entry.model_id)
            cars.append(model_car(name, model.info))
            plans.append(CarPlan(name, entry.id, model=checked_model_bytes(storage, model)))
        else:
            if slot.get("bot") not in BOT_LEVELS:
                raise ValueError(f"unknown bot {slot.get('bot')!r} in job {job.id}")
            cars.append(bot_car(name, slot["bot"]))
            plans.append(CarPlan(name, None, bot=slot["bot"]))
    slots = len(lineup(job))
    while job.kind == "round" and len(cars) < 2:  # suspensions emptied the grid: a bot fills it
        name = car_name({}, slots + len(cars))
        cars.append(bot_car(name, event.round_bot))
        plans.append(CarPlan(name, None, bot=event.round_bot))
    config = RaceConfig.build(**event.ruleset, cars=cars, seed=job.seed)
    return RacePlan(config, tuple(plans), step_budget_ms, step_window)


def encode_plan(plan: RacePlan) -> bytes:
    """``plan`` as bytes: an 8-byte header length, a JSON header, then the model files."""
    cars = [
        [c.name, c.entry_id, c.bot, None if c.model is None else len(c.model)] for c in plan.cars
    ]
    head = json.dumps(
        {
            "config": json.loads(plan.config.to_json()),
            "cars": cars,
            "step_budget_ms": plan.step_budget_ms,
            "step_window": plan.step_window,
        }
    ).encode()
    models = b"".join(c.model for c in plan.cars if c.model is not None)
    return len(head).to_bytes(8, "big") + head + models


def decode_plan(data: bytes) -> RacePlan:
    """The plan :func:`encode_plan` wrote."""
    offset = 8 + int.from_bytes(data[:8], "big")
    head = json.loads(data[8:offset])
    cars = []
    for name, entry_id, bot, size in head["cars"]:
        model = None if size is None else data[offset : offset + size]
        offset += size or 0
        cars.append(CarPlan(name, entry_id, model=model, bot=bot))
    config = RaceConfig.model_validate(head["config"])
    return RacePlan(config, tuple(cars), head.get("step_budget_ms"), head.get("step_window", 10))


def policies(plan: RacePlan) -> dict[str, Policy]:
    """Drivers for a plan (call in the sandbox: this runs submitted graphs).

    Model files were fully validated when stored and the plan's bytes were checked against
    that sha256 (:func:`checked_model_bytes`), so only the static checks run again here.
    """
    from submissions import load_policy

    drivers: dict[str, Policy] = {}
    track = None
    for car, spec in zip(plan.cars, plan.config.cars, strict=True):
        if car.model is not None:
            # A graph can still output NaN on a real race's observations (the validator
            # tries random ones): the runner raises rather than letting the car drive on
            # sanitised garbage, and the race's guard (RacePlan.guard) retires the car.
            drivers[car.name] = load_policy(
                car.model, non_finite="raise", name=f"car {car.name}", run_policy=False
            )
        else:
            if track is None:
                track = resolve_track(plan.config)[0]
            drivers[car.name] = bot_driver(str(car.bot), track, spec.action_space)
    return drivers
