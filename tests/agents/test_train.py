"""Training: PPO learns, clone, resume, the CLI's outputs and its error messages."""

from __future__ import annotations

import json
import zipfile
from copy import deepcopy
from dataclasses import replace
from pathlib import Path

import onnx
import pytest
import torch
from deepracer.logs import DeepRacerLog
from typer.testing import CliRunner

import arena
from agents.action_spaces import parse_action_space_spec
from agents.cli import app
from agents.evaluate import EvalSummary
from agents.hyperparameters import Hyperparameters
from agents.privileged import PRIVILEGED_SIZE
from agents.run import Run
from agents.selfplay import read_policy_graph
from agents.settings import TrainSettings, load_settings
from agents.train import Trainer
from agents.vecenv import RacingVecEnv
from submissions.format import POLICY_MEMBER
from submissions.validator import validate
from tests.agents.clones import assert_clone_takes_the_actor

SPACE = parse_action_space_spec("3x3@1.0")
TINY = Hyperparameters(num_episodes_between_training=2, num_epochs=2, batch_size=64)


def _settings(**kw) -> TrainSettings:
    base = {
        "action_space": SPACE,
        "sensors": ("lidar",),
        "workers": 0,
        "races": 1,
        "eval_every": 1000,
        "eval_time_limit": 5.0,
    }
    return TrainSettings(**{**base, **kw})


FAST_REWARD = """
def reward_function(params):
    return 1.0 if params["speed"] >= 1.0 else 0.1
"""


def _mean_step_reward(act, reward: str, steps: int = 300) -> float:
    """Mean reward per step of ``act(obs) -> one-hot actions`` on two fixed-seed races."""
    config = arena.make_config(mode="training", action_space=SPACE, seed=11)
    env = RacingVecEnv(config, reward, num_races=2, num_workers=0)
    try:
        obs, total = env.get_observations(), 0.0
        for _ in range(steps):
            obs, rewards, *_ = env.step(act(obs))
            total += float(rewards.mean())
        return total / steps
    finally:
        env.close()


@pytest.mark.slow
@pytest.mark.parametrize("sync", [True, False], ids=["sync", "overlapped"])
def test_ppo_beats_a_random_policy(tmp_path, sync: bool):
    """PPO must beat uniform random actions by 1.8x in reward per step, collecting and
    updating in turn or at once.

    Lidar sees no track edges on an empty track (every beam reads the 1 m clip), so the
    reward here depends on the action itself (full speed pays 1.0, else 0.1), which a
    blind policy can learn; random actions earn about 0.4 per step. The discount is 0.9
    because each step's reward is its own: with DeepRacer's 0.999 the returns of 1,500
    samples hardly tell the actions apart (1.1-1.7x over seeds 0-2, either critic); with
    0.9 seeds 0-2 reached 2.2-2.4x with either critic.
    """
    torch.manual_seed(0)
    reward = tmp_path / "fast.py"
    reward.write_text(FAST_REWARD)
    hp = Hyperparameters(
        batch_size=128, num_epochs=5, lr=1e-3, beta_entropy=0.0, discount_factor=0.9
    )
    settings = _settings(races=2, iterations=6, steps_per_env=128, reward_fn=str(reward), sync=sync)
    Trainer(settings, tmp_path / "run", hp).run()
    actor = Run.load(tmp_path / "run").actor()
    gen = torch.Generator().manual_seed(1)

    def random_act(obs):
        index = torch.randint(0, SPACE.n, (obs.batch_size[0],), generator=gen)
        return torch.nn.functional.one_hot(index, SPACE.n).float()

    def trained_act(obs):
        with torch.inference_mode():
            return actor(obs, stochastic_output=True)

    random_reward = _mean_step_reward(random_act, str(reward))
    trained_reward = _mean_step_reward(trained_act, str(reward))
    assert trained_reward > 1.8 * random_reward, (trained_reward, random_reward)


def test_clone_with_changed_speed_range(tmp_path):
    Trainer(_settings(iterations=1), tmp_path / "a", TINY).run()
    faster = _settings(iterations=1, action_space=parse_action_space_spec("3x3@2.0"))
    trainer = Trainer(faster, tmp_path / "b", TINY, clone=tmp_path / "a")
    assert_clone_takes_the_actor(trainer, tmp_path / "a")
    other = _settings(iterations=1, action_space=parse_action_space_spec("5x2@2.0"))
    trainer = Trainer(other, tmp_path / "c", TINY, clone=tmp_path / "a")
    with pytest.raises(ValueError, match="cannot clone"):
        trainer.run()


def test_a_privileged_critic_trains_resumes_clones_and_exports_a_sensor_only_model(tmp_path):
    """The critic reads the privileged state; the packed model reads only the sensors."""
    privileged = _settings(iterations=1, critic="privileged")
    run = tmp_path / "privileged"
    result = Trainer(privileged, run, TINY).run()
    critic = torch.load(run / "checkpoints" / "last.pt", weights_only=True)["critic_state_dict"]
    first_layer = next(v for k, v in critic.items() if k.endswith("weight"))
    assert first_layer.shape[1] == PRIVILEGED_SIZE
    graph = onnx.load_from_string(read_policy_graph(result.model_zip))
    assert [i.name for i in graph.graph.input] == ["lidar"]
    assert load_settings(run).critic == "privileged"
    Trainer(privileged, run, TINY, resume=True).run()  # loads the privileged critic, strict
    assert torch.load(run / "checkpoints" / "last.pt", weights_only=True)["iteration"] == 1

    Trainer(_settings(iterations=1, critic="sensors"), tmp_path / "sensors", TINY).run()
    trainer = Trainer(privileged, tmp_path / "clone", TINY, clone=tmp_path / "sensors")
    # the actor only: the parent's critic reads lidar
    assert_clone_takes_the_actor(trainer, tmp_path / "sensors")


def test_ctrl_c_keeps_the_last_finished_iteration(tmp_path):
    def interrupt(stats):
        raise KeyboardInterrupt

    result = Trainer(_settings(iterations=5), tmp_path / "run", TINY).run(interrupt)
    assert result.interrupted and result.iterations == 1
    ckpt = torch.load(tmp_path / "run" / "checkpoints" / "last.pt", weights_only=True)
    assert ckpt["iteration"] == 0
    assert result.model_zip is not None and result.model_zip.exists()


@pytest.mark.slow
def test_cli_train_writes_every_output(tmp_path):
    hp_file = tmp_path / "hp.json"
    hp_file.write_text(TINY.model_dump_json())
    run = tmp_path / "runs" / "tiny"
    cli = CliRunner()
    args = ["train", "--out", str(run), "--sensors", "lidar", "--action-space", "3x3@1.0"]
    args += ["--reward-fn", "follow_center_line", "--iterations", "2", "--workers", "0"]
    args += ["--eval-every", "1", "--eval-time-limit", "10", "--hyperparameters", str(hp_file)]
    result = cli.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "drives blind" in result.output  # lidar alone sees nothing on a time trial
    for name in ("0-iteration.csv", "1-iteration.csv"):
        assert (run / "0" / "training-simtrace" / name).stat().st_size > 0
    metadata = json.loads((run / "model" / "model_metadata.json").read_text())
    assert metadata["action_space_type"] == "discrete" and metadata["sensor"] == ["LIDAR"]
    assert json.loads((run / "ip" / "hyperparameters.json").read_text())["num_epochs"] == 2
    evaluations = sorted(run.glob("evaluation-*/evaluation-simtrace/0-iteration.csv"))
    assert evaluations
    assert len((run / "metrics.csv").read_text().splitlines()) == 3
    assert (run / "reward_graph.png").stat().st_size > 0
    assert list((run / "tensorboard").glob("events.out.tfevents.*"))
    assert (run / "checkpoints" / "last.pt").exists()
    # deepracer-utils, the community's log analysis, reads it as a deepracer-for-cloud run.
    training = DeepRacerLog(model_folder=str(run))
    evaluation = DeepRacerLog(model_folder=str(run))
    training.load_training_trace()
    evaluation.load_evaluation_trace()
    traces = list((run / "0" / "training-simtrace").glob("*.csv"))
    rows = sum(len(trace.read_text().splitlines()) - 1 for trace in traces)
    assert len(training.dataframe()) == rows and set(training.dataframe()["iteration"]) == {0, 1}
    assert len(evaluation.dataframe()) > 0
    from arena import make_config
    from arena.config import NO_VARIATION
    from arena.race import run_race
    from submissions import load_policy, validate

    model_zip = run / "model" / "model.zip"
    assert validate(model_zip).ok
    policy = load_policy(model_zip)  # the round trip: trained, packed, validated, loaded, raced
    race = make_config(sensors=policy.info.sensors, action_space=policy.info.action_space)
    race = race.model_copy(update={"laps": 1, "time_limit_s": 5.0, "variation": NO_VARIATION})
    raced = run_race(race, {"car0": policy})  # the round trip, on the fixed start
    assert raced.car("car0").distance > 0.5

    resumed = cli.invoke(app, ["train", "--out", str(run), "--resume", "--iterations", "1"])
    assert resumed.exit_code == 0, resumed.output
    assert len((run / "metrics.csv").read_text().splitlines()) == 4
    ckpt = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    assert ckpt["iteration"] == 2

    again = cli.invoke(app, args)  # a fresh run into the same folder is refused, not appended
    assert again.exit_code == 2 and "already holds a training run" in again.output
    assert len((run / "metrics.csv").read_text().splitlines()) == 4

    shown = cli.invoke(app, ["evaluate", str(run), "--laps", "1", "--time-limit", "10"])
    assert shown.exit_code == 0, shown.output
    assert "off" in shown.output and list(run.glob("evaluation-*/replay.gif"))


def _train_briefly(tmp_path, reward_fn: str):
    """``slipstream train`` for one lidar iteration in-process with ``--reward-fn``."""
    args = ["train", "--out", str(tmp_path / "run"), "--sensors", "lidar"]
    args += ["--reward-fn", reward_fn, "--iterations", "1", "--workers", "0"]
    return CliRunner().invoke(app, args)


@pytest.mark.parametrize(
    ("source", "message"),
    [
        ("def reward_function(params):\n    return 1.0 +\n", "line 2"),
        ("def reward(params):\n    return 1.0\n", "reward_function"),
        ("def reward_function(params):\n    return float('nan')\n", "finite"),
    ],
)
def test_cli_reports_reward_function_errors(tmp_path, source, message):
    reward = Path(tmp_path) / "reward.py"
    reward.write_text(source)
    result = _train_briefly(tmp_path, str(reward))
    assert result.exit_code == 2
    assert "error" in result.output and message in result.output


def test_cli_reports_unknown_sample(tmp_path):
    result = _train_briefly(tmp_path, "no_such_sample")
    assert result.exit_code == 2 and "no_such_sample" in result.output


def test_cli_under_torchrun_without_gpus_says_what_to_do(tmp_path, monkeypatch):
    monkeypatch.setenv("WORLD_SIZE", "2")
    monkeypatch.setenv("LOCAL_RANK", "1")
    args = ["train", "--out", str(tmp_path / "run"), "--iterations", "1", "--workers", "0"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2 and "--device cuda" in result.output
    assert not (tmp_path / "run").exists()


def test_iterations_report_typed_stats_and_evaluations_checkpoint(tmp_path):
    seen = []
    settings = _settings(iterations=3, eval_every=2)
    result = Trainer(settings, tmp_path / "run", TINY).run(seen.append)
    assert [s.iteration for s in seen] == [0, 1, 2]
    assert [s.eval is not None for s in seen] == [False, True, True]  # every 2nd, and the last
    assert result.evaluations == seen[1:] and result.iterations == 3
    assert result.elapsed_s == seen[-1].elapsed_s
    rows = (tmp_path / "run" / "metrics.csv").read_text().splitlines()
    assert len(rows) == 4 and rows[1].split(",")[7] == ""  # no evaluation after iteration 0
    ckpt = torch.load(tmp_path / "run" / "checkpoints" / "last.pt", weights_only=True)
    assert ckpt["iteration"] == 2 and ckpt["elapsed_s"] == seen[-1].elapsed_s


def test_a_minutes_budget_ends_with_an_evaluation(tmp_path):
    seen = []
    settings = _settings(minutes=0.001, eval_every=1000)  # spent by the first iteration
    Trainer(settings, tmp_path / "run", TINY).run(seen.append)
    assert len(seen) == 1 and seen[-1].eval is not None
    assert (tmp_path / "run" / "checkpoints" / "last.pt").exists()


def test_an_iteration_ending_just_inside_the_minutes_is_not_the_last_unevaluated(
    tmp_path, monkeypatch
):
    """The clock is read once per iteration: an iteration that ends just before the budget
    is spent is followed by one more, evaluated as the last (a run that stopped at the
    next reading of the clock kept no evaluated checkpoint, so no ``best``)."""

    class SteppedClock:
        """25 s pass between two readings: iteration 0 ends at 50 s, a minute's budget
        is spent at the next reading."""

        def __init__(self) -> None:
            self.now = 0.0

        def monotonic(self) -> float:
            self.now += 25.0
            return self.now

    monkeypatch.setattr("agents.train.time", SteppedClock())
    seen = []
    Trainer(_settings(minutes=1, eval_every=1000), tmp_path / "run", TINY).run(seen.append)
    assert seen[0].elapsed_s < 60.0 and seen[0].eval is None
    assert len(seen) == 2 and seen[-1].eval is not None
    assert (tmp_path / "run" / "checkpoints" / "best.pt").exists()


def test_ctrl_c_during_an_update_keeps_the_weights_it_started_from(tmp_path, monkeypatch):
    from agents.runner import RacingRunner

    finished = {}
    real_iteration = RacingRunner.iteration

    def interrupted_second_update(runner, it):
        if it == 1:
            finished.update(deepcopy(runner.alg.get_policy().state_dict()))
            real_iteration(runner, it)  # the weights change ...
            raise KeyboardInterrupt  # ... and Ctrl-C arrives before the iteration is done
        return real_iteration(runner, it)

    monkeypatch.setattr(RacingRunner, "iteration", interrupted_second_update)
    result = Trainer(_settings(iterations=5), tmp_path / "run", TINY).run()
    assert result.interrupted and result.iterations == 1
    ckpt = torch.load(tmp_path / "run" / "checkpoints" / "last.pt", weights_only=True)
    assert ckpt["iteration"] == 0 and finished
    for key, value in finished.items():
        assert torch.equal(ckpt["actor_state_dict"][key], value), key


def _eval(
    progress: float, incidents: int = 0, total: float | None = None, lap: float | None = None
) -> EvalSummary:
    laps = int(progress // 100 * 3)
    return EvalSummary(laps, progress, lap, total, incidents, 0, incidents, "finished")


def test_an_evaluation_is_ranked_by_progress_then_incidents_then_finish_time():
    ranked = [_eval(50.0), _eval(100.0, 2, 30.0), _eval(100.0, 0, 40.0), _eval(100.0, 0, 35.0)]
    assert sorted(ranked, key=lambda e: e.score) == ranked


def test_an_evaluation_on_several_tracks_is_ranked_over_all_of_its_races():
    """--eval-also-tracks: progress is the races' mean, incidents and finish times add up;
    clean only if every race is."""
    fast_here = replace(_eval(100.0, 0, 30.0), also=(_eval(100.0, 1, 50.0),))
    clean_both = replace(_eval(100.0, 0, 32.0), also=(_eval(100.0, 0, 52.0),))
    unfinished = replace(_eval(100.0, 0, 20.0), also=(_eval(50.0),))
    assert sorted([clean_both, fast_here, unfinished], key=lambda e: e.score) == [
        unfinished,
        fast_here,
        clean_both,
    ]
    assert unfinished.score[0] == 75.0 and clean_both.score == (100.0, -0.0, -84.0)
    assert clean_both.clean(3) and not fast_here.clean(3) and not unfinished.clean(3)


def test_the_packed_model_is_the_best_evaluation_s_and_resume_keeps_it(tmp_path, monkeypatch):
    """model.zip, evaluate and --clone take checkpoints/best.pt; --resume takes last.pt."""
    scripted = [_eval(30.0), _eval(100.0, 2, 30.0), _eval(100.0, 0, 40.0), _eval(50.0)]
    monkeypatch.setattr(Trainer, "_evaluate", lambda trainer, runner: scripted.pop(0))
    run = tmp_path / "run"
    result = Trainer(_settings(iterations=3, eval_every=1), run, TINY).run()
    best = torch.load(run / "checkpoints" / "best.pt", weights_only=True)
    last = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    assert (best["iteration"], last["iteration"]) == (2, 2)
    Trainer(_settings(iterations=1, eval_every=1), run, TINY, resume=True).run()  # eval 50%
    best = torch.load(run / "checkpoints" / "best.pt", weights_only=True)
    last = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    assert (best["iteration"], last["iteration"]) == (2, 3) and not scripted
    assert best["eval_score"] == list(_eval(100.0, 0, 40.0).score)

    actor = Run.load(run).actor()
    for key, value in actor.state_dict().items():
        assert torch.equal(value, best["actor_state_dict"][key]), key
    assert any(
        not torch.equal(value, last["actor_state_dict"][key])
        for key, value in actor.state_dict().items()
    )
    with zipfile.ZipFile(result.model_zip) as packed:  # repacked by the resumed run
        summary = json.loads(packed.read("model_metadata.json"))["slipstream"]["training"]
    assert summary["iterations"] == 3  # best.pt's iteration 2, counted from 1


def test_the_fastest_lap_s_checkpoint_is_kept_and_each_checkpoint_packs(tmp_path, monkeypatch):
    """best.pt by completion, fastest.pt by evaluation lap (kept across a resume), last.pt;
    pack_checkpoints packs each as a valid submission of its own weights."""
    scripted = [
        _eval(100.0, 0, 40.0, lap=13.0),  # best by completion, fastest so far
        _eval(100.0, 2, 33.0, lap=10.5),  # two off-tracks: not the best, but the fastest lap
        _eval(60.0),  # no lap: neither
        _eval(100.0, 1, 35.0, lap=11.0),  # resumed: slower than 10.5
    ]
    monkeypatch.setattr(Trainer, "_evaluate", lambda trainer, runner: scripted.pop(0))
    run = tmp_path / "run"
    Trainer(_settings(iterations=3, eval_every=1), run, TINY).run()
    Trainer(_settings(iterations=1, eval_every=1), run, TINY, resume=True).run()
    assert not scripted

    kept = Run.load(run).pack_checkpoints(tmp_path / "models")
    by_name = {c["name"]: c for c in kept}
    assert [c["name"] for c in kept] == ["best", "fastest", "last"]
    assert [by_name[n]["iteration"] for n in ("best", "fastest", "last")] == [0, 1, 3]
    assert (by_name["best"]["best_lap"], by_name["fastest"]["best_lap"]) == (13.0, 10.5)
    assert by_name["fastest"]["completion"] == 100.0 and by_name["last"]["best_lap"] is None
    assert json.loads((tmp_path / "models" / "index.json").read_text()) == kept

    graphs = set()
    for name in ("best", "fastest", "last"):
        archive = tmp_path / "models" / f"{name}.zip"
        report = validate(archive)
        assert report.ok, (name, report.problems)
        with zipfile.ZipFile(archive) as packed:
            summary = json.loads(packed.read("model_metadata.json"))["slipstream"]["training"]
            graphs.add(packed.read(POLICY_MEMBER))
        assert summary["iterations"] == by_name[name]["iteration"] + 1
    assert len(graphs) == 3  # three different sets of weights
    # the model's own checkpoint is the run's model.zip, byte for byte (one league model)
    assert (tmp_path / "models" / "best.zip").read_bytes() == Run.load(run).model_zip.read_bytes()
