"""Ratings over 30 head-to-model rounds of real races: equal models stay together, a clearly
stronger one pulls ahead.

Each round is planned as the scheduler plans it (``plan_round`` from the current ratings,
seeded by event and round, the previous round's pairings damped; seeds from
``round_seeds``), every race is a real ``arena.run_race`` (PyBullet), and its finish
positions go through ``league.ranking.rate``, as ``rate_race`` does for stored races. Two
models and k = 1 make one race a round: 30 real races per test.

Intervals are ``mu ± 2 sigma``.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from pathlib import Path

import pytest

from arena.actions import default_discrete_space
from arena.config import RaceConfig, resolve_track
from arena.policy import Policy
from arena.pursuit import PurePursuitPolicy
from arena.race import run_race
from league.jobs.evaluation import car_name
from league.jobs.matchmaking import Candidate, pairings, plan_round
from league.jobs.scheduler import round_seeds
from league.ranking import Skill, initial_skill, rate
from submissions import load_policy, pack
from tests.league.conftest import CREATED_AT, policy_onnx

pytestmark = pytest.mark.slow
EVENT_ID, ROUNDS = 1, 30
RULES = {"track": "beginner_loop", "race_type": "head_to_model", "laps": 1, "time_limit_s": 20.0}
Drivers = Callable[[RaceConfig], dict[int, Policy]]


def interval(skill: Skill) -> tuple[float, float]:
    """The rating interval these tests compare: mu ± 2 sigma."""
    return skill.mu - 2 * skill.sigma, skill.mu + 2 * skill.sigma


def season(drivers: Drivers) -> tuple[dict[int, Skill], dict[int, int]]:
    """Ratings after ``ROUNDS`` rounds of entries 1 and 2, and each entry's wins."""
    skills = {1: initial_skill(), 2: initial_skill()}
    wins = {1: 0, 2: 0}
    previous: list[list[dict]] = []
    used: list[int] = []
    for number in range(1, ROUNDS + 1):
        field = [Candidate(e, s.mu, s.sigma) for e, s in skills.items()]
        rng = random.Random(f"{EVENT_ID}:{number}")
        grids = plan_round(field, k=1, max_cars=2, rng=rng, recent=pairings(previous))
        seeds = round_seeds(EVENT_ID, number, len(grids), used)
        for grid, seed in zip(grids, seeds, strict=True):
            names = {slot["entry_id"]: car_name(slot, i) for i, slot in enumerate(grid)}
            entries = list(names)
            cars = [{"name": name, "sensors": ["lidar"]} for name in names.values()]
            config = RaceConfig.build(**RULES, cars=cars, seed=seed)
            by_entry = drivers(config)
            policies = {names[e]: by_entry[e] for e in entries}
            result = run_race(config, policies, record_trace=False)
            place = {c.name: c.finish_position for c in result.cars}
            positions = [place[names[e]] for e in entries]
            new = rate([skills[e] for e in entries], positions)
            skills.update(zip(entries, new, strict=True))
            wins[entries[positions.index(1)]] += 1
        previous, used = grids, used + seeds
    return skills, wins


def model_file(folder: Path, seed: int) -> bytes:
    """A submission archive (the tiny lidar MLP for ``seed``) as it is uploaded."""
    path = folder / f"m{seed}.zip"
    pack(path, policy_onnx(seed), default_discrete_space(), ["lidar"], created_at=CREATED_AT)
    return path.read_bytes()


def test_the_same_model_entered_twice_keeps_overlapping_intervals(tmp_path: Path) -> None:
    archive = model_file(tmp_path, 3)  # one file, entered twice: two equally strong models
    drivers = {1: load_policy(archive), 2: load_policy(archive)}
    skills, wins = season(lambda config: drivers)
    (lo1, hi1), (lo2, hi2) = interval(skills[1]), interval(skills[2])
    print(f"equal: {wins} wins, entry1 [{lo1:.2f}, {hi1:.2f}], entry2 [{lo2:.2f}, {hi2:.2f}]")
    assert skills[1].races == skills[2].races == ROUNDS
    assert lo1 < hi2 and lo2 < hi1  # the intervals overlap
    assert skills[1].sigma < 0.6 * initial_skill().sigma  # ... though 30 races firmed them up


def test_a_clearly_stronger_driver_pulls_ahead(tmp_path: Path) -> None:
    crawler = load_policy(model_file(tmp_path, 3))  # the untrained MLP: it barely moves

    def drivers(config: RaceConfig) -> dict[int, Policy]:
        track, _ = resolve_track(config)
        return {1: PurePursuitPolicy(track, config.cars[0].action_space), 2: crawler}

    skills, wins = season(drivers)
    (lo1, hi1), (lo2, hi2) = interval(skills[1]), interval(skills[2])
    print(f"stronger: {wins} wins, entry1 [{lo1:.2f}, {hi1:.2f}], entry2 [{lo2:.2f}, {hi2:.2f}]")
    assert lo1 > hi2  # pure pursuit's interval lies wholly above the slow follower's
    assert skills[1].ordinal > skills[2].mu
