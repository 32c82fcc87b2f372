"""Test data for the web pages: events filled with races from real ``arena.run_race`` runs."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agents.action_spaces import continuous_action_space
from arena.actions import default_discrete_space
from arena.config import NO_VARIATION, RaceConfig, resolve_track
from arena.drivers import LaneFollowerPolicy, nearest_action
from arena.pursuit import PurePursuitPolicy
from arena.race import RaceResult, run_race
from league import crud
from league.models import Event
from submissions import pack
from tests.league.conftest import CREATED_AT, League, policy_onnx
from tests.league.helpers import create_event, enter, record_as_worker, upload

METRICS_CSV = "iteration,mean_reward,mean_progress,eval_progress\n" + "".join(
    f"{i},{10 + 4 * i},{min(100, 8 * i)},{'' if i % 3 else min(100, 9 * i)}\n" for i in range(13)
)


class Swerve:
    """A lane follower that steers full lock for a few steps (20: the steering lags its
    command by 0.5 s): it leaves the track once."""

    needs_params = True

    def __init__(self, follower: LaneFollowerPolicy, start: int, steps: int) -> None:
        self.follower, self.start, self.steps, self.step = follower, start, steps, 0

    def reset(self) -> None:
        """Start counting steps again."""
        self.step = 0

    def act(self, observation: dict[str, Any], params: dict[str, Any] | None = None) -> Any:
        """Full left lock inside the window, the lane follower elsewhere."""
        self.step += 1
        if self.start <= self.step < self.start + self.steps:
            return nearest_action(self.follower.space, 30.0, 1.0)
        return self.follower.act(observation, params)


@dataclass
class Site:
    """What the web tests navigate: event, race and model ids, and who owns what."""

    time_trial: int = 0
    head_to_head: int = 0
    races: dict[str, int] = field(default_factory=dict)
    models: dict[str, int] = field(default_factory=dict)
    entries: dict[str, int] = field(default_factory=dict)


def race(event: Event, drivers: dict[str, tuple[float, int | None]], seed: int) -> RaceResult:
    """Run one real race of ``event``: car name -> (speed, swerve step or None).

    The start is the fixed grid in the listed order and commands are applied as given
    (``NO_VARIATION``), so that the scripted swerve and finishing order happen as written.
    """
    ruleset = {**event.ruleset, "variation": NO_VARIATION}
    config = RaceConfig.build(**ruleset, cars=[{"name": n} for n in drivers], seed=seed)
    track, _ = resolve_track(config)
    policies: dict[str, Any] = {}
    for car in config.cars:
        speed, swerve_at = drivers[car.name]
        follower = LaneFollowerPolicy(track, car.action_space, speed=speed)
        policies[car.name] = follower if swerve_at is None else Swerve(follower, swerve_at, 20)
    return run_race(config, policies)


def duel(event: Event, fast: str, slow: str, seed: int = 0) -> RaceResult:
    """A real race of ``event`` in which ``fast`` (pure pursuit capped at 3 m/s) starts behind
    ``slow`` (capped at 0.7 m/s), gets by on the outside and, in a race of two laps or more,
    runs into it when lapping it.

    The grid keeps the listed order (``slow`` in front) instead of the one the seed draws.
    """
    caps = {slow: 0.7, fast: 3.0}
    spaces = {name: continuous_action_space(speed_high=cap) for name, cap in caps.items()}
    ruleset = dict(event.ruleset)
    ruleset["variation"] = {**ruleset.get("variation", {}), "shuffle_grid": False}
    config = RaceConfig.build(
        **ruleset,
        cars=[{"name": name, "action_space": space} for name, space in spaces.items()],
        seed=seed,
    )
    track, _ = resolve_track(config)
    policies = {name: PurePursuitPolicy(track, space) for name, space in spaces.items()}
    return run_race(config, policies)


def record(league: League, event_id: int, result: RaceResult, entries: dict[str, int]) -> int:
    """Store a race through its job, as a worker does (head-to-head races rated)."""
    return record_as_worker(league, event_id, result, entries)


def model_with_metrics(folder: Path) -> Path:
    """A valid submission that carries a training ``metrics.csv``."""
    folder.mkdir(parents=True, exist_ok=True)
    space = default_discrete_space()
    out = folder / "with-metrics.zip"
    return pack(
        out, policy_onnx(7), space, ["lidar"], metrics_csv=METRICS_CSV, created_at=CREATED_AT
    )


def populate(league: League) -> Site:
    """A one-lap time trial raced by alice and bob (carol entered, not raced yet: the tests
    race her later) and a head-to-head event of alice and bob with two races."""
    site = Site()
    with league.sessions() as session:
        racer, token = crud.create_racer(session, "carol")
        league.tokens["carol"], league.ids["carol"] = token, racer.id
    for who, seed in (("alice", 11), ("bob", 12), ("carol", 13)):
        site.models[who] = upload(league, who, seed, name=f"{who}-model")["id"]
    common = {"laps": 1, "seeds": [0], "time_limit_s": 60.0}
    site.time_trial = create_event(league, name="Autumn Time Trial", **common)["id"]
    site.head_to_head = create_event(
        league, name="Head-to-Head Cup", race_type="head_to_model", **common
    )["id"]
    for who in ("alice", "bob", "carol"):
        entry = enter(league, who, site.time_trial, site.models[who])
        site.entries[who] = entry["entry_id"]
    with league.sessions() as session:
        event = session.get(Event, site.time_trial)
        session.expunge(event)
    for who, speed, swerve in (("alice", 0.8, None), ("bob", 0.8, 40)):
        result = race(event, {who: (speed, swerve)}, seed=0)
        site.races[who] = record(league, site.time_trial, result, {who: site.entries[who]})
    h2h = {
        who: enter(league, who, site.head_to_head, site.models[who])["entry_id"]
        for who in ("alice", "bob")
    }
    with league.sessions() as session:
        event = session.get(Event, site.head_to_head)
        session.expunge(event)
    for seed in (0, 1):
        result = race(event, {"alice": (0.8, None), "bob": (0.8, 40 + 30 * seed)}, seed=seed)
        site.races[f"h2h{seed}"] = record(league, site.head_to_head, result, h2h)
    return site
