"""Racing metrics: who passed whom on track, who caused each contact, who led each lap."""

from __future__ import annotations

from arena.racing_metrics import CarStep, Contact, RacingMetrics

GRID = {"a": 0.0, "b": -0.8}  # b starts 0.8 m behind a


def _step(distance: float, status: str = "in_progress", laps: int = 0, contacts=()) -> CarStep:
    return CarStep(distance=distance, laps=laps, status=status, contacts=tuple(contacts))


def _drive(metrics: RacingMetrics, rows: list[dict[str, CarStep]]) -> None:
    for i, steps in enumerate(rows):
        metrics.update(0.1 * (i + 1), steps)


def test_a_pass_on_track_counts_for_both_cars_and_is_an_event() -> None:
    metrics = RacingMetrics(GRID)
    # b gains 0.3 m a step on a: level after ~3 steps, clearly ahead after 4.
    _drive(metrics, [{"a": _step(0.1 * i), "b": _step(0.4 * i)} for i in range(1, 8)])
    assert metrics.cars["b"].overtakes == 1 and metrics.cars["b"].times_overtaken == 0
    assert metrics.cars["a"].times_overtaken == 1 and metrics.cars["a"].overtakes == 0
    [event] = metrics.events
    assert (event.kind, event.car, event.other, event.at_fault) == ("overtake", "b", "a", False)
    assert 0.3 < event.t < 0.6


def test_the_grid_offset_decides_who_is_ahead_not_the_distance_from_ones_own_start() -> None:
    metrics = RacingMetrics(GRID)
    # b has driven 0.5 m more than a but is still 0.3 m behind it on the track.
    rows = [{"a": _step(0.1 * i), "b": _step(0.1 * i + 0.1 * min(i, 5))} for i in range(10)]
    _drive(metrics, rows)
    assert metrics.cars["b"].overtakes == 0 and metrics.events == []


def test_swapping_places_back_and_forth_counts_each_pass() -> None:
    metrics = RacingMetrics({"a": 0.0, "b": 0.0})
    lead = [0.0, 0.2, 0.2, -0.2, -0.2, 0.2]  # a's lead over b, step by step
    _drive(metrics, [{"a": _step(1.0 + d), "b": _step(1.0)} for d in lead])
    assert metrics.cars["a"].overtakes == 1 and metrics.cars["b"].overtakes == 1
    assert [e.car for e in metrics.events] == ["b", "a"]


def test_jitter_within_the_margin_is_not_a_pass() -> None:
    metrics = RacingMetrics({"a": 0.0, "b": 0.0})
    wobble = [0.02 * (-1) ** i for i in range(20)]  # 2 cm either way: within the 5 cm margin
    _drive(metrics, [{"a": _step(2.0 + d), "b": _step(2.0)} for d in wobble])
    assert metrics.events == []


def test_a_pass_needs_more_than_five_centimetres_either_way() -> None:
    """A car that draws level, gets its nose 3 cm ahead and falls back has not passed; one
    that gets 8 cm ahead has. The same for the car passed back: first b passes a, then a
    passes b back."""
    metrics = RacingMetrics({"a": 0.0, "b": 0.0})  # level: grid order puts a ahead
    lead = [0.5, 0.5, 0.5]  # a's lead over b, step by step: a ahead, both settled
    lead += [0.1, -0.03, 0.1, 0.5]  # b draws level, 3 cm ahead, falls back: no pass
    lead += [-0.08, -0.5]  # b gets 8 cm ahead: b passes a
    lead += [-0.1, 0.03, -0.1, -0.5]  # a draws level, 3 cm ahead, falls back: no pass
    lead += [0.08, 0.5]  # a gets 8 cm ahead: a passes b back
    _drive(metrics, [{"a": _step(2.0 + d), "b": _step(2.0)} for d in lead])
    assert [(e.car, e.other) for e in metrics.events] == [("b", "a"), ("a", "b")]
    assert [round(e.t, 1) for e in metrics.events] == [0.8, 1.4]
    assert metrics.cars["a"].overtakes == metrics.cars["b"].overtakes == 1


def test_passing_a_car_serving_a_penalty_does_not_count() -> None:
    metrics = RacingMetrics(GRID)
    rows = [{"a": _step(1.0), "b": _step(0.5)}]
    rows += [{"a": _step(1.0, "pause"), "b": _step(0.5 + 0.3 * i)} for i in range(1, 6)]
    rows += [{"a": _step(1.0 + 0.1 * i), "b": _step(2.0 + 0.3 * i)} for i in range(1, 4)]
    _drive(metrics, rows)
    assert metrics.cars["b"].overtakes == 0 and metrics.cars["a"].times_overtaken == 0
    assert metrics.events == []


def test_a_respawn_jump_is_not_a_pass_but_a_later_pass_on_track_is() -> None:
    metrics = RacingMetrics({"a": 0.0, "b": 0.0})
    rows = [{"a": _step(2.0), "b": _step(1.0)}]
    # a crashes and is put back 2 m behind b: b is ahead without passing anyone...
    rows += [{"a": _step(-1.0, "crashed"), "b": _step(1.1)}]
    rows += [{"a": _step(-1.0, "pause"), "b": _step(1.2)}]
    # ...then a comes back on track and passes b for real.
    rows += [{"a": _step(-1.0 + 0.5 * i), "b": _step(1.2 + 0.1 * i)} for i in range(1, 10)]
    _drive(metrics, rows)
    assert metrics.cars["b"].overtakes == 0
    assert metrics.cars["a"].overtakes == 1 and metrics.cars["b"].times_overtaken == 1


def test_a_car_moved_when_it_rejoins_neither_passes_nor_is_passed() -> None:
    metrics = RacingMetrics({"a": 0.0, "b": 0.0})
    rows = [{"a": _step(1.0 + 0.1 * i), "b": _step(1.2 + 0.1 * i)} for i in range(4)]
    rows += [{"a": _step(1.4), "b": _step(1.5, "off_track")}]  # b is ahead...
    rows += [{"a": _step(1.5), "b": _step(1.5, "pause")}]
    rows += [{"a": _step(1.6), "b": _step(1.5, "in_progress")}]  # ...released...
    rows += [{"a": _step(1.7), "b": _step(1.2, "in_progress")}]  # ...moved back to a free spot
    rows += [{"a": _step(1.8 + 0.1 * i), "b": _step(1.3 + 0.1 * i)} for i in range(5)]
    rows += [{"a": _step(2.3), "b": _step(3.0)}]  # b, racing again for a while, passes a
    _drive(metrics, rows)
    assert metrics.cars["a"].overtakes == 0 and metrics.cars["b"].times_overtaken == 0
    assert metrics.cars["b"].overtakes == 1


def test_a_car_must_have_been_racing_for_three_steps_to_pass() -> None:
    metrics = RacingMetrics({"a": 0.0, "b": 0.0})
    rows = [
        {"a": _step(1.0), "b": _step(0.9)},
        {"a": _step(1.1), "b": _step(0.9, "off_track")},
        {"a": _step(1.2), "b": _step(0.9, "in_progress")},
        {"a": _step(1.3), "b": _step(1.5, "in_progress")},  # moved as it rejoined
    ]
    _drive(metrics, rows)
    assert metrics.cars["b"].overtakes == 0


def test_repeated_touching_is_one_collision_and_a_new_touch_is_another() -> None:
    metrics = RacingMetrics(GRID)
    behind = [Contact("a", at_fault=True)]
    ahead = [Contact("b", at_fault=False)]
    touching = {"a": _step(1.0, contacts=ahead), "b": _step(0.3, contacts=behind)}
    apart = {"a": _step(1.0), "b": _step(0.1)}
    _drive(metrics, [touching, touching, touching, apart, touching, touching])
    assert metrics.cars["b"].at_fault_collisions == 2
    assert metrics.cars["a"].at_fault_collisions == 0
    contacts = [e for e in metrics.events if e.kind == "contact"]
    assert [(e.car, e.other, e.at_fault) for e in contacts] == [("b", "a", True)] * 2
    assert [round(e.t, 1) for e in contacts] == [0.1, 0.5]


def test_a_contact_nobody_caused_is_marked_without_fault_and_boxes_count() -> None:
    metrics = RacingMetrics({"a": 0.0})
    rows = [
        {"a": _step(1.0, contacts=[Contact("bot0", at_fault=False)])},
        {"a": _step(1.1)},
        {"a": _step(1.2, "crashed", contacts=[Contact("box3", at_fault=True)])},
    ]
    _drive(metrics, rows)
    assert metrics.cars["a"].at_fault_collisions == 1
    assert [(e.other, e.at_fault) for e in metrics.events] == [("bot0", False), ("box3", True)]


def test_each_lap_is_led_by_the_first_car_to_complete_it() -> None:
    metrics = RacingMetrics(GRID)
    rows = [
        {"a": _step(10.0, laps=1), "b": _step(9.0)},  # a completes lap 1 first
        {"a": _step(11.0, laps=1), "b": _step(10.2, laps=1)},
        {"a": _step(19.5, laps=1), "b": _step(20.4, laps=2)},  # b completes lap 2 first
        {"a": _step(20.1, laps=2), "b": _step(20.4, laps=2)},
        {"a": _step(30.3, laps=3), "b": _step(30.1, laps=3)},  # same step: a is further past
    ]
    _drive(metrics, rows)
    assert (metrics.cars["a"].laps_led, metrics.cars["b"].laps_led) == (2, 1)
