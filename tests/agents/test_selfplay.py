"""Self-play opponents run on the submissions runner, zeroing non-finite outputs."""

from __future__ import annotations

import math

import numpy as np

from agents.selfplay import opponent_policy
from submissions import OnnxRunner
from tests.submissions.test_runner import identity


def test_opponents_drive_greedily_and_zero_non_finite_outputs() -> None:
    discrete = opponent_policy(identity(3), discrete=True, name="snapshot:4")
    assert isinstance(discrete, OnnxRunner) and discrete.non_finite == "zero"
    assert discrete.act({"lidar": np.array([0.1, 0.7, 0.2], np.float32)}) == 1
    assert discrete.act({"lidar": [0.1, math.nan, 0.2]}) == 2
    continuous = opponent_policy(identity(2), discrete=False)
    action = continuous.act({"lidar": [math.inf, -3.0]})
    assert action.dtype == np.float32
    np.testing.assert_array_equal(action, [0.0, -1.0])

