"""The head-to-head gauntlet's field for a model on a discrete action space.

``benchmarks/`` is a folder of scripts, not a package, so the gauntlet is loaded from its file.
"""

from __future__ import annotations

import importlib.util
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

from agents.action_spaces import console_action_space
from arena.config import CarConfig
from arena.pursuit import PurePursuitPolicy
from tracks.catalog import get_track

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


@pytest.fixture(scope="module")
def gauntlet() -> Iterator[ModuleType]:
    """``benchmarks/h2h_gauntlet.py`` as a module (it imports its harness by name)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.syspath_prepend(str(BENCHMARKS))
        path = BENCHMARKS / "h2h_gauntlet.py"
        spec = importlib.util.spec_from_file_location("benchmarks_h2h_gauntlet", path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        patch.setitem(sys.modules, spec.name, module)  # dataclasses look their module up
        spec.loader.exec_module(module)
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
