"""The privileged state a critic reads: where the car is, how the road bends, what is near."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import arena
from agents.action_spaces import parse_action_space_spec
from agents.privileged import AHEAD, LOOKAHEAD_M, PRIVILEGED_GROUP, PRIVILEGED_SIZE, SIGHT_M
from agents.privileged import privileged_state as state_of
from agents.vecenv import PASS_GAP_M, RacingVecEnv
from tracks.track import Track


def _stadium(straight: float = 8.0, radius: float = 2.0, half_width: float = 0.5) -> Track:
    """A counter-clockwise loop: two straights joined by half circles."""
    n = 24
    bottom = np.stack([np.linspace(0.0, straight, n, endpoint=False), np.zeros(n)], 1)
    turn = np.linspace(-math.pi / 2, math.pi / 2, n, endpoint=False)
    right_end = np.stack([straight + radius * np.cos(turn), radius + radius * np.sin(turn)], 1)
    top = np.stack([np.linspace(straight, 0.0, n, endpoint=False), np.full(n, 2 * radius)], 1)
    left_end = np.stack([-radius * np.cos(turn), radius - radius * np.sin(turn)], 1)
    centre = np.vstack([bottom, right_end, top, left_end, bottom[:1]])
    tangent = np.gradient(centre, axis=0)
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], 1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    left, right = centre + half_width * normal, centre - half_width * normal
    return Track.from_arrays("stadium", centre, left, right)


TRACK = _stadium()
N = len(LOOKAHEAD_M)
SIN = slice(1, 1 + N)
COS = slice(1 + N, 1 + 2 * N)
OBJECTS = 1 + 2 * N + 4  # first object feature


def _params(s: float, offset: float = 0.0, turn_deg: float = 0.0, objects=(), speed=2.0):
    """Reward params of a car at arc ``s``, ``offset`` m left of the centre, pointing
    ``turn_deg`` left of the road; ``objects`` are ``(arc, offset, speed)``."""
    _, heading = TRACK.pose_at(s)
    return {
        "track_width": TRACK.width,
        "projection_distance": s,
        "heading": math.degrees(float(heading)) + turn_deg,
        "speed": speed,
        "steering_angle": 15.0,
        "all_wheels_on_track": True,
        "progress": 100.0 * s / TRACK.length,
        "distance_from_center": abs(offset),
        "is_left_of_center": offset > 0,
        "objects_distance": [a for a, _, _ in objects],
        "objects_distance_from_center": [abs(o) for _, o, _ in objects],
        "objects_left_of_center": [o > 0 for _, o, _ in objects],
        "objects_speed": [v for _, _, v in objects],
    }


def test_the_vector_says_where_the_car_is_and_how_the_road_bends_ahead():
    straight, bend = 1.0, 6.0  # 5 m of straight ahead; the left half circle 2 m ahead
    on_straight = state_of(TRACK, _params(straight, offset=0.25 * TRACK.width))
    assert on_straight.shape == (PRIVILEGED_SIZE,) and on_straight.dtype == np.float32
    assert on_straight[0] == pytest.approx(0.5)  # half-way to the left edge
    assert np.allclose(on_straight[SIN], 0.0, atol=0.05)
    assert np.allclose(on_straight[COS], 1.0, atol=0.01)
    assert on_straight[1 + 2 * N] == pytest.approx(0.5)  # 2 m/s of 4
    right_of_centre = state_of(TRACK, _params(straight, offset=-0.25 * TRACK.width))
    assert right_of_centre[0] == pytest.approx(-0.5)
    before_bend = state_of(TRACK, _params(bend))
    assert np.allclose(before_bend[SIN][:3], 0.0, atol=0.05)  # up to 1 m: straight
    # 3 m ahead is 1 m into the left half circle: the road has turned 1 m / 2 m = 0.5 rad.
    assert before_bend[SIN][-1] == pytest.approx(math.sin(0.5), abs=0.06)
    skewed = state_of(TRACK, _params(straight, turn_deg=30.0))  # nose 30 degrees left
    assert np.allclose(skewed[SIN], -0.5, atol=0.05)


def test_objects_ahead_nearest_first_then_the_one_behind_and_none_out_of_sight():
    s = 5.0
    objects = [
        (s + 3.0, -0.2, 0.0),  # a box 3 m ahead, right of the centre
        (s + 1.5, 0.2, 1.0),  # a car 1.5 m ahead, left, at 1 m/s
        (s - 1.0, 0.0, 3.0),  # a car 1 m behind at 3 m/s
        (s + SIGHT_M + 1.0, 0.0, 0.0),  # out of sight
    ]
    params = _params(s, objects=objects)
    rows = state_of(TRACK, params)[OBJECTS:].reshape(AHEAD + 1, 4)
    half = 0.5 * TRACK.width
    assert rows[0] == pytest.approx([1.0, 1.5 / SIGHT_M, 0.2 / half, (1.0 - 2.0) / 4.0])
    assert rows[1] == pytest.approx([1.0, 3.0 / SIGHT_M, -0.2 / half, -2.0 / 4.0])
    assert rows[2] == pytest.approx([1.0, -1.0 / SIGHT_M, 0.0, 1.0 / 4.0])
    alone = state_of(TRACK, _params(s, objects=objects[3:]))
    assert not alone[OBJECTS:].any()


def test_gaps_are_taken_across_the_start_line():
    near_end = TRACK.length - 0.5
    params = _params(near_end, objects=[(0.5, 0.0, 0.0)])  # 1 m ahead, past the line
    rows = state_of(TRACK, params)[OBJECTS:].reshape(AHEAD + 1, 4)
    assert rows[0][:2] == pytest.approx([1.0, 1.0 / SIGHT_M])


def test_vec_env_adds_the_group_only_when_asked_and_rivals_see_each_other():
    """Head to model: the learner restarts behind its rival, so each sees the other."""
    config = arena.make_config(
        track="beginner_loop",
        race_type="head_to_model",
        sensors=("lidar",),
        action_space=parse_action_space_spec("3x3@1.0"),
        mode="training",
        seed=4,
    )
    plain = RacingVecEnv(config, "follow_center_line", num_races=1, num_workers=0)
    try:
        assert PRIVILEGED_GROUP not in plain.get_observations()
    finally:
        plain.close()
    env = RacingVecEnv(config, "follow_center_line", num_races=1, num_workers=0, privileged=True)
    try:
        obs = env.get_observations()
        assert obs[PRIVILEGED_GROUP].shape == (env.num_envs, PRIVILEGED_SIZE)
        objects = obs[PRIVILEGED_GROUP][:, OBJECTS:].reshape(env.num_envs, AHEAD + 1, 4)
        # Two cars on a start grid: each has the other in sight, ahead or behind.
        assert bool((objects[:, :, 0].sum(dim=1) == 1).all())
        gaps = objects[:, :, 1].sum(dim=1) * SIGHT_M
        assert float(gaps.abs().max()) < 2 * PASS_GAP_M
        actions = torch.zeros(env.num_envs, env.num_actions)
        actions[:, 4] = 1.0
        for _ in range(10):
            obs, *_ = env.step(actions)
        assert bool(obs[PRIVILEGED_GROUP][:, 1 + 2 * N].gt(0).all())  # both are moving
    finally:
        env.close()
