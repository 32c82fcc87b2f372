"""The rsl-rl VecEnv adapter: shapes, dones, auto-reset, workers and opponents."""

from __future__ import annotations

import re

import pytest
import torch
from tensordict import TensorDict

import arena
from agents import networks
from agents.export import export_onnx
from agents.selfplay import Opponent
from agents.settings import SLOTS_PER_WORKER
from agents.vecenv import GRID_EVERY, PASS_GAP_M, RacingVecEnv
from arena.actions import ContinuousActionSpace, default_discrete_space
from arena.spawn import GRID_GAP_M

SPACE = default_discrete_space()


def _config(**kw):
    kw.setdefault("action_space", SPACE)
    return arena.make_config(track="beginner_loop", mode="training", seed=3, **kw)


def _one_hot(env: RacingVecEnv, index: int) -> torch.Tensor:
    actions = torch.zeros(env.num_envs, env.num_actions)
    actions[:, index] = 1.0
    return actions


def _drive(env: RacingVecEnv, steps: int, index: int) -> list[tuple]:
    out = []
    for _ in range(steps):
        out.append(env.step(_one_hot(env, index)))
    return out


@pytest.mark.parametrize("workers", [0, 2])
def test_shapes_dones_and_auto_reset(workers):
    env = RacingVecEnv(
        _config(sensors=("lidar",)), "follow_center_line", num_races=2, num_workers=workers
    )
    try:
        assert env.num_envs == 2 and env.num_actions == SPACE.n
        obs = env.get_observations()
        assert isinstance(obs, TensorDict) and obs["lidar"].shape == (2, 64)
        # hard left at the highest speed leaves the track within a few seconds
        results = _drive(env, 90, index=1)
        dones = torch.stack([r[2] for r in results])
        assert dones.any(dim=0).all(), "every slot should end an episode"
        obs, rewards, done, extras = results[-1]
        assert rewards.shape == (2,) and done.shape == (2,)
        assert extras["time_outs"].shape == (2,) and extras["time_outs"].dtype == torch.bool
        logs = [r[3]["log"] for r in results if "log" in r[3]]
        assert logs and set(logs[0]) == {
            "/episode/reward",
            "/episode/progress",
            "/episode/lap_completion",
        }
        episodes = env.pop_episodes()
        assert len(episodes) == int(dones.sum())
        assert all(e["status"] == "off_track" for e in episodes)
        rows = env.drain_simtrace()
        assert len(rows) == 90 * 2 and {"episode", "X", "done", "tstamp"} <= set(rows[0])
        assert (env.episode_length_buf < 90).all()  # restarted after their episodes ended
    finally:
        env.close()


def test_default_races_share_each_worker():
    """Without ``num_races``, every worker (or the trainer, in-process) steps races for
    ``SLOTS_PER_WORKER`` learner cars, each race with its own seed."""
    env = RacingVecEnv(_config(sensors=("lidar",)), "follow_center_line", num_workers=0)
    try:
        assert env.num_races == env.num_envs == SLOTS_PER_WORKER > 1
        seeds = [race.config.seed for race in env._local.envs]
        assert seeds[0] == 3 and len(set(seeds)) == SLOTS_PER_WORKER
    finally:
        env.close()
    two_learners = _config(race_type="head_to_model", num_cars=2, sensors=("lidar",))
    env = RacingVecEnv(two_learners, "follow_center_line", num_workers=0)
    try:
        assert env.num_envs == SLOTS_PER_WORKER and env.num_races == SLOTS_PER_WORKER // 2
    finally:
        env.close()


def test_races_take_the_tracks_in_turn():
    """``also_tracks`` puts the races on ``--track`` and the further tracks in turn, each
    race driven and judged on its own track."""
    env = RacingVecEnv(
        _config(sensors=("lidar",)),
        "follow_center_line",
        num_races=3,
        num_workers=0,
        also_tracks=["slipstream_speedway"],
    )
    try:
        tracks = [race.track.name for race in env._local.envs]
        assert tracks == ["beginner_loop", "slipstream_speedway", "beginner_loop"]
        _drive(env, 20, index=SPACE.n // 2)
        lengths = [env._local.last_info[(i, "car0")]["params"]["track_length"] for i in range(3)]
        assert lengths[0] == lengths[2] != lengths[1]
    finally:
        env.close()
    with pytest.raises(ValueError, match="3 tracks need at least 3 races"):
        RacingVecEnv(
            _config(sensors=("lidar",)),
            "follow_center_line",
            num_races=2,
            num_workers=0,
            also_tracks=["slipstream_speedway", "grand_tour"],
        )


def test_camera_and_continuous_actions():
    space = ContinuousActionSpace()
    env = RacingVecEnv(
        _config(sensors=("camera", "lidar"), action_space=space),
        "follow_center_line",
        num_races=1,
        num_workers=0,
    )
    try:
        obs = env.get_observations()
        assert obs["camera"].shape == (1, 1, 120, 160) and obs["camera"].dtype == torch.float32
        assert float(obs["camera"].min()) >= 0.0 and float(obs["camera"].max()) <= 1.0
        with torch.inference_mode():  # as in rsl-rl's rollout
            obs, *_ = env.step(torch.tensor([[5.0, -5.0]]))  # clipped to [-1, 1]
        assert obs["lidar"].shape == (1, 64)
    finally:
        env.close()


def test_reward_errors_in_process_name_the_race_car_step_and_line(tmp_path):
    """In-process (``num_workers=0``); through worker processes: test_train_workers.py."""
    bad = tmp_path / "reward.py"
    # Fine on the load-time pre-check's steps 1-5, dividing by zero on step 9 of the race.
    bad.write_text("def reward_function(params):\n    return 1.0 / (params['steps'] - 9)\n")
    env = RacingVecEnv(_config(sensors=("lidar",)), str(bad), num_races=1, num_workers=0)
    message = f"race 0: reward function of car 'car0' raised at step 9 ({bad}, line 2): "
    try:
        with pytest.raises(RuntimeError, match=re.escape(message + "ZeroDivisionError")):
            for _ in range(9):
                env.step(_one_hot(env, 4))
    finally:
        env.close()


def test_head_to_model_with_frozen_opponent():
    config = _config(race_type="head_to_model", num_cars=2, sensors=("lidar",))
    env = RacingVecEnv(
        config, "follow_center_line", num_races=2, num_workers=0, learner_cars=["car0"]
    )
    try:
        assert env.num_envs == 2  # one learner slot per race; car1 is an opponent
        torch.manual_seed(0)  # the same opponent, so the same restarts, every run
        actor = networks.build_actor("dense 256-256", ("lidar",), SPACE)
        graph = export_onnx(actor, ("lidar",), SPACE)
        env.set_opponents({0: Opponent("snapshot:0", graph), 1: Opponent("snapshot:0", graph)})
        near, grid = [], []  # the rival's distance ahead of each restarted learner
        for _ in range(90):
            _, _, dones, _ = env.step(_one_hot(env, 1))  # the learners circle off the road
            for i in dones.nonzero().flatten().tolist():
                race = env._local.envs[i]
                if "car1" not in race.agents:
                    continue  # the opponent's episode ended too: a plain restart
                me = env._local.last_info[(i, "car0")]["params"]
                rival = env._local.last_info[(i, "car1")]["params"]
                length = me["track_length"]
                gap = rival["projection_distance"] - me["projection_distance"]
                standing = rival["steps"] == 0  # the rival was restarted with the learner
                (grid if standing else near).append((gap + length / 2) % length - length / 2)
                assert me["is_left_of_center"] != rival["is_left_of_center"]
        # Restarted behind the rival (to follow or pass it) and ahead of it (to lead), never
        # alongside on this 0.76 m track, and every GRID_EVERY-th time both standing on a
        # grid, the learner in the back slot.
        assert [abs(g) for g in near] == pytest.approx([PASS_GAP_M] * len(near), abs=0.15)
        assert min(near) < 0 < max(near)
        assert len(grid) >= 2 and grid == pytest.approx([GRID_GAP_M] * len(grid), abs=0.1)
        assert len(near) >= (GRID_EVERY - 1) * (len(grid) - 1)
        episodes = env.pop_episodes()
        assert episodes and all(e["opponent"] == "snapshot:0" for e in episodes)
        assert all(isinstance(e["win"], bool) for e in episodes)
    finally:
        env.close()


def test_a_paced_racer_drives_clean_and_learners_restart_beside_it_on_a_wide_track():
    """On DeepRacer's width a learner restarts behind, ahead of and alongside its rival in
    turn; the pool's paced pure-pursuit racer drives the opponent car on the road."""
    config = arena.make_config(
        track="slipstream_speedway",
        mode="training",
        seed=3,
        race_type="head_to_model",
        num_cars=2,
        sensors=("lidar",),
        action_space=SPACE,
    )
    env = RacingVecEnv(
        config, "follow_center_line", num_races=1, num_workers=0, learner_cars=["car0"]
    )
    try:
        env.set_opponents({0: Opponent("pursuit:60%", pace=0.6)})
        race = env._local.envs[0]
        near, rival_arcs, off_road = [], [], 0
        for _ in range(240):
            _, _, dones, _ = env.step(_one_hot(env, 1))  # the learner circles off the road
            rival = env._local.last_info[(0, "car1")]["params"]
            off_road += not rival["all_wheels_on_track"]
            rival_arcs.append(rival["projection_distance"])
            if dones[0] and "car1" in race.agents and rival["steps"] > 0:
                me = env._local.last_info[(0, "car0")]["params"]
                length = me["track_length"]
                gap = rival["projection_distance"] - me["projection_distance"]
                near.append((gap + length / 2) % length - length / 2)
                assert me["is_left_of_center"] != rival["is_left_of_center"]
        assert off_road == 0
        assert max(rival_arcs) - min(rival_arcs) > 5.0  # it races on, 60% of the line's pace
        behind = [g for g in near if g > PASS_GAP_M / 2]
        ahead = [g for g in near if g < -PASS_GAP_M / 2]
        alongside = [g for g in near if abs(g) < 0.15]
        assert behind and ahead and alongside, near
        assert len(behind) + len(ahead) + len(alongside) == len(near)
        assert {e["opponent"] for e in env.pop_episodes()} == {"pursuit:60%"}
    finally:
        env.close()


def test_shared_self_play_makes_every_car_a_slot():
    config = _config(race_type="head_to_model", num_cars=2, sensors=("lidar",))
    env = RacingVecEnv(config, "follow_center_line", num_races=1, num_workers=0)
    try:
        assert env.num_envs == 2
        obs, rewards, dones, _ = env.step(_one_hot(env, 4))
        assert dones.shape == (2,)
        assert rewards.shape == (2,) and obs["lidar"].shape == (2, 64)
    finally:
        env.close()
