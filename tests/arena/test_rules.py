"""The episode rules, step by step, without physics."""

from __future__ import annotations

import pytest

from arena.config import Penalties
from arena.rules import STUCK_STEPS, Measurement, RuleBook
from tracks.track import Track

LENGTH = 20.0
# A 6 m x 4 m rectangle: a loop exactly LENGTH metres long.
LOOP = Track.from_arrays(
    "rectangle",
    [[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [0.0, 4.0], [0.0, 0.0]],
    [[0.3, 0.3], [5.7, 0.3], [5.7, 3.7], [0.3, 3.7], [0.3, 0.3]],
    [[-0.3, -0.3], [6.3, -0.3], [6.3, 4.3], [-0.3, 4.3], [-0.3, -0.3]],
)
DT = 1 / 15


def book(mode: str = "race", laps: int = 1, max_resets: int | None = None) -> RuleBook:
    return RuleBook(LOOP, mode, laps, Penalties(), max_resets, time_limit_s=60.0)


def drive(rules: RuleBook, rec, arcs, on_track=True, crashed=False, t0=0.0):
    statuses = []
    t = t0
    last = rec.last_arc
    for arc in arcs:
        t += DT
        statuses.append(
            rules.update(rec, Measurement(arc % LENGTH, abs(arc - last), on_track, crashed), t)
        )
        last = arc
    return statuses, t


def test_lap_completes_when_progress_reaches_100_across_the_start_line() -> None:
    rules = book()
    rec = rules.start(arc=18.0, now=0.0)
    statuses, _ = drive(rules, rec, [18.0 + 0.5 * i for i in range(1, 41)])
    assert statuses[-1] == "lap_complete" and rec.done and rec.finished
    assert rec.laps == 1
    assert rec.lap_times[0] == pytest.approx(40 * DT)
    assert statuses[:-1] == ["in_progress"] * 39


def test_every_lap_of_a_multi_lap_race_is_marked_lap_complete() -> None:
    rules = book(laps=3)
    rec = rules.start(arc=0.0, now=0.0)
    statuses, _ = drive(rules, rec, [0.5 * i for i in range(1, 121)])
    marked = [i for i, status in enumerate(statuses) if status == "lap_complete"]
    assert marked == [39, 79, 119]  # 20 m laps at 0.5 m a step
    assert rec.laps == 3 and rec.done and rec.finished
    assert statuses[40] == "in_progress"


def test_progress_is_percent_of_lap_from_start_point() -> None:
    rules = book()
    rec = rules.start(arc=10.0, now=0.0)
    drive(rules, rec, [15.0])
    assert rules.progress(rec) == pytest.approx(25.0)


def test_training_ends_on_first_off_track() -> None:
    rules = book(mode="training")
    rec = rules.start(0.0, 0.0)
    statuses, _ = drive(rules, rec, [0.1, 0.2], on_track=False)
    assert statuses == ["off_track", "off_track"]  # a finished episode stays finished
    assert rec.done and rec.off_track_count == 1 and rec.steps == 1


def test_race_freezes_for_the_penalty_then_continues() -> None:
    rules = book()
    rec = rules.start(0.0, 0.0)
    statuses, t = drive(rules, rec, [0.1], on_track=False)
    assert statuses == ["off_track"] and rec.frozen and not rec.done
    pause_steps = int(round(Penalties().off_track_s / DT))
    statuses, t = drive(rules, rec, [0.1] * pause_steps, t0=t)
    assert statuses[:-1] == ["pause"] * (pause_steps - 1)
    assert statuses[-1] == "in_progress" and not rec.frozen
    assert rec.penalty_seconds == Penalties().off_track_s
    assert rec.reset_count == 1


def test_immobilised_after_15_still_steps() -> None:
    rules = book(mode="training")
    rec = rules.start(5.0, 0.0)
    statuses, _ = drive(rules, rec, [5.0] * STUCK_STEPS)
    assert statuses[-1] == "immobilized"
    assert statuses[:-1] == ["in_progress"] * (STUCK_STEPS - 1)


def test_reversed_after_15_steps_of_falling_progress() -> None:
    rules = book(mode="training")
    rec = rules.start(5.0, 0.0)
    statuses, _ = drive(rules, rec, [5.0 - 0.05 * i for i in range(1, STUCK_STEPS + 1)])
    assert statuses[-1] == "reversed"


def test_rule_order_lap_before_off_track_and_off_track_before_crash() -> None:
    rules = book(mode="training")
    rec = rules.start(0.0, 0.0)
    statuses, _ = drive(rules, rec, [0.5], on_track=False, crashed=True)
    assert statuses == ["off_track"] and rec.crash_count == 0
    rec = rules.start(19.9, 0.0)
    rec.distance = LENGTH - 0.05
    statuses, _ = drive(rules, rec, [19.95], on_track=False)
    assert statuses == ["lap_complete"]


def test_crash_penalty_and_max_resets() -> None:
    rules = book(max_resets=1)
    rec = rules.start(0.0, 0.0)
    _, t = drive(rules, rec, [0.1], crashed=True)
    assert rec.crash_count == 1 and rec.penalty_seconds == Penalties().crash_s
    _, t = drive(rules, rec, [0.1] * int(round(Penalties().crash_s / DT)), t0=t)
    drive(rules, rec, [0.2], crashed=True, t0=t)
    assert rec.done and not rec.finished and rec.reset_count == 2


def test_time_up_truncates() -> None:
    rules = RuleBook(LOOP, "race", 3, Penalties(), None, time_limit_s=1.0)
    rec = rules.start(0.0, 0.0)
    statuses, _ = drive(rules, rec, [0.01 * i for i in range(1, 16)])
    assert statuses[-1] == "time_up" and rec.truncated and rec.done
