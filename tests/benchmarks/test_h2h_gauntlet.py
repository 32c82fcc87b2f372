"""The head-to-head gauntlet's field for a model on a discrete action space."""

from __future__ import annotations

from collections.abc import Iterator
from types import ModuleType

import pytest

from agents.action_spaces import console_action_space
from arena.config import CarConfig
from arena.pursuit import PurePursuitPolicy
from tests.benchmarks.scripts import benchmark_script
from tracks.catalog import get_track


@pytest.fixture(scope="module")
def gauntlet() -> Iterator[ModuleType]:
    """``benchmarks/h2h_gauntlet.py`` as a module."""
    with benchmark_script("h2h_gauntlet") as module:
        yield module


def test_a_discrete_model_gets_its_field_paced_by_the_scripted_drivers_own_lap(
    gauntlet: ModuleType,
) -> None:
    """A model on a discrete space laps alone and gets its paced rivals: the pursuit
    driver's own lap is measured in the scripted drivers' car, not in the model's space."""
    track = "slipstream_speedway"
    space = console_action_space(30.0, 5, 3.0, 3)
    car = CarConfig(name=gauntlet.ME, action_space=space)
    model = PurePursuitPolicy(get_track(track), space)
    notes: list[str] = []

    solo, heats = gauntlet.field_on(track, model, car, 1, [], notes)

    assert solo is not None and solo > 0
    assert any("the pursuit driver alone" in note for note in notes)
    paced = [h for h in heats if h.name.startswith("pursuit ")]
    assert [h.name for h in paced] == [gauntlet.paced_name(p) for p in gauntlet.PACES]
    assert all(h.car.action_space == gauntlet.SCRIPTED_SPACE for h in heats)
