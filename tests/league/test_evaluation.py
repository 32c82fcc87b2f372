"""League races load submitted models with the "raise" non-finite rule."""

from __future__ import annotations

import numpy as np
import pytest

import arena
from league.jobs.evaluation import CarPlan, RacePlan, policies
from submissions import NonFiniteOutput, load_policy
from tests.league_ops.hostile import nan_onnx
from tests.submissions.test_support import pack_bytes


def test_a_model_that_outputs_nan_in_a_race_fails_it_by_name() -> None:
    archive = pack_bytes(nan_onnx(), sensors=("lidar",))  # valid: finite on random input
    config = arena.make_config(sensors=("lidar",))
    drivers = policies(RacePlan(config, (CarPlan("entry7", 7, model=archive),)))
    driver = drivers["entry7"]
    assert isinstance(driver.act({"lidar": np.full(64, 0.5, np.float32)}), int)
    open_road = {"lidar": np.ones(64, np.float32)}  # every beam reads 1.0: the graph's NaN
    with pytest.raises(NonFiniteOutput) as caught:
        driver.act(open_road)
    assert str(caught.value) == "car entry7: the model output NaN or inf at step 2"
    assert isinstance(load_policy(archive).act(open_road), int)  # the default rule drives on
