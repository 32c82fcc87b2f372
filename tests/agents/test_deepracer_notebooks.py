"""A run read by deepracer-utils as the DeepRacer log-analysis notebooks read it.

A small clockwise loop is imported as a user track, trained on with two worker processes,
evaluated (``slipstream evaluate`` and a pure-pursuit race written by ``agents.evaluate``),
and the run folder goes through the notebooks' calls: training trace and its aggregation,
evaluation trace, its aggregation and plots, the metrics file, the agent and the world.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest
import yaml
from deepracer.logs import AnalysisUtils, DeepRacerLog, PlottingUtils
from deepracer.logs.metrics import TrainingMetrics
from deepracer.tracks import TrackIO
from typer.testing import CliRunner

from agents import evaluate
from agents.action_spaces import parse_action_space_spec
from agents.cli import app
from agents.hyperparameters import Hyperparameters
from agents.rewards import resolve_reward
from agents.settings import TrainSettings
from agents.train import Trainer
from arena.config import resolve_track
from arena.pursuit import PurePursuitPolicy
from tracks.catalog import get_track, import_track

TRACK = "cw_test_loop"
SPACE = parse_action_space_spec("3x3@1.0")
# Pays 1 unless the params say the car drives against the file's waypoint order.
REWARD = """
def reward_function(params):
    return 2.0 if params["is_reversed"] else 1.0
"""


def _clockwise_loop(path: Path, a: float = 3.0, b: float = 2.0, width: float = 1.07) -> Path:
    """A DeepRacer ``.npy`` ellipse whose centre line runs clockwise (first row repeated)."""
    theta = -np.linspace(0.0, 2.0 * math.pi, 81)  # decreasing angle: clockwise
    unit = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    centre = unit * [a, b]
    inner = unit * [a - width / 2, b - width / 2]  # the loop's inside, whatever the direction
    outer = unit * [a + width / 2, b + width / 2]
    np.save(path, np.hstack([centre, inner, outer]))
    return path


@pytest.mark.slow
def test_notebooks_read_a_two_worker_run(tmp_path, monkeypatch):
    monkeypatch.setenv("SLIPSTREAM_HOME", str(tmp_path / "home"))
    npy_dir = tmp_path / "npy"
    npy_dir.mkdir()
    import_track(_clockwise_loop(npy_dir / f"{TRACK}.npy"))
    assert get_track(TRACK).direction == "cw"
    reward = tmp_path / "not_reversed.py"
    reward.write_text(REWARD)

    run = tmp_path / "run"
    settings = TrainSettings(
        track=TRACK,
        sensors=("lidar",),
        action_space=SPACE,
        reward_fn=str(reward),
        workers=2,
        races=2,
        iterations=3,
        eval_every=1000,  # the last iteration evaluates anyway
        eval_laps=1,
        eval_time_limit=10.0,
    )
    hp = Hyperparameters(num_episodes_between_training=2, num_epochs=2, batch_size=64)
    Trainer(settings, run, hp).run()

    result = CliRunner().invoke(app, ["evaluate", str(run), "--laps", "1", "--time-limit", "8"])
    assert result.exit_code == 0, result.output
    config = evaluate.evaluation_config(TRACK, "time_trial", ("lidar",), SPACE, laps=3)
    pursuit = PurePursuitPolicy(resolve_track(config)[0], SPACE)
    race = evaluate.evaluate_policy(config, pursuit, reward_function=resolve_reward(str(reward)))
    assert race.cars[0].laps == 3
    pursuit_folder = evaluate.write_evaluation(run, race)

    # Training trace: every (episode, steps) once, each episode's rows whole per iteration.
    log = DeepRacerLog(model_folder=str(run))
    log.load_training_trace()
    df = log.dataframe()
    assert len(df) == 3 * 64 * 2
    assert not df.duplicated(["episode", "steps"]).any()
    assert (df["reward"] == 1.0).all(), "is_reversed must be False on a cw file driven cw"
    agg = AnalysisUtils.simulation_agg(df)
    rows = df.groupby(["iteration", "episode"]).size().rename("rows").reset_index()
    merged = agg.merge(rows, on=["iteration", "episode"])
    assert len(merged) == len(agg) and (merged["steps"] == merged["rows"]).all()
    for _, episode in df.groupby("episode"):
        steps = episode["steps"].to_numpy()
        assert (np.diff(steps) == 1).all()
    assert log.agent_and_network()["sensor_list"] == ["LIDAR"]

    # The world: deepracer-for-cloud's training_params.yaml names the track.
    params = yaml.safe_load((run / "training_params.yaml").read_text())
    assert params["WORLD_NAME"] == TRACK and params["REVERSE_DIR"] == "false"

    # Evaluation traces: one episode per lap; the pursuit's 3 laps are 3 complete episodes.
    evaluation = DeepRacerLog(model_folder=str(run))
    evaluation.load_evaluation_trace()
    edf = evaluation.dataframe()
    assert edf["stream"].nunique() == 3  # training's evaluation, the CLI's, the pursuit's
    stream = pursuit_folder.name.removeprefix("evaluation-")
    laps = edf[edf["stream"] == stream].copy()
    assert sorted(laps["episode"].unique()) == [0, 1, 2]
    assert (laps["reward"] == 1.0).all()
    for _, lap in laps.groupby("episode"):
        assert lap["steps"].iloc[0] == 1 and lap["progress"].iloc[-1] == 100.0
        assert lap["progress"].iloc[0] < 5.0
        assert lap["episode_status"].iloc[-1] == "lap_complete" and lap["done"].iloc[-1]
    eagg = AnalysisUtils.simulation_agg(edf, "stream", add_tstamp=True, is_eval=True)
    pursuit_agg = eagg[eagg["stream"] == stream]
    assert len(pursuit_agg) == 3 and (pursuit_agg["complete"] == 1).all()
    # a lap's time sums its steps' tstamp deltas (the first lap's first delta is from the
    # stream before, so it is left out)
    assert np.allclose(pursuit_agg["time"].to_numpy()[1:], race.cars[0].lap_times[1:])
    npy_tracks = TrackIO(base_path=str(npy_dir))
    PlottingUtils.plot_evaluations(laps, npy_tracks.load_track(TRACK))

    # Metrics: training episodes = finished episodes in the trace, plus the evaluation laps.
    metrics = TrainingMetrics(None, fname=str(run / "metrics" / "TrainingMetrics.json"))
    training = metrics.getTraining()
    assert len(training) == int(df["done"].sum())
    assert list(training["episode"]) == list(range(1, len(training) + 1))
    assert len(metrics.getEvaluation()) >= 1
    assert not metrics.getSummary().empty
    evaluation_files = sorted((run / "metrics").glob("EvaluationMetrics-*.json"))
    assert len(evaluation_files) == 2  # the CLI's and the pursuit's, not training's
    pursuit_metrics = json.loads(evaluation_files[-1].read_text())["metrics"]
    assert [m["trial"] for m in pursuit_metrics] == [1, 2, 3]
    assert {m["episode_status"] for m in pursuit_metrics} == {"Lap complete"}
    assert [m["elapsed_time_in_milliseconds"] for m in pursuit_metrics] == [
        round(t * 1000) for t in race.cars[0].lap_times
    ]
