"""Training as it runs: worker processes, their failures, Ctrl-C, and PFSP's weights."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

import arena
from agents.action_spaces import parse_action_space_spec
from agents.hyperparameters import Hyperparameters
from agents.selfplay import OpponentPool, pfsp_weights
from agents.settings import TrainSettings
from agents.train import Trainer
from agents.vecenv import RacingVecEnv
from slipstream.cli import app
from submissions import validate

SPACE = parse_action_space_spec("3x3@1.0")
TINY = Hyperparameters(num_episodes_between_training=2, num_epochs=2, batch_size=64)
RAISING_REWARD = """
def reward_function(params):
    if params["steps"] >= 9:
        raise ValueError(f"wheel sensor unplugged at step {params['steps']}")
    return 1.0
"""


# ------------------------------------------------------------------ processes
def _children(pid: int) -> dict[int, str]:
    """Live (not zombie) child processes of ``pid``: pid -> command line (from /proc)."""
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        state, ppid = stat.rsplit(")", 1)[1].split()[:2]
        if int(ppid) == pid and state != "Z":
            found[int(entry.name)] = cmdline
    return found


def _workers(pid: int) -> set[int]:
    """``pid``'s multiprocessing workers (spawned children; not the resource tracker)."""
    return {p for p, cmd in _children(pid).items() if "spawn_main" in cmd}


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def _wait_gone(pids: set[int], seconds: float = 15.0) -> set[int]:
    """The ``pids`` still alive after waiting up to ``seconds`` for them to exit."""
    deadline = time.monotonic() + seconds
    while (left := {p for p in pids if _alive(p)}) and time.monotonic() < deadline:
        time.sleep(0.1)
    return left


# ---------------------------------------------- 1. same seed, same rollouts
def _rollout(workers: int, steps: int = 300) -> tuple[list, list[dict]]:
    """Random actions (fixed seed) on two 2-car races; per-step tensors and simtrace rows."""
    config = arena.make_config(
        track="beginner_loop",
        race_type="head_to_model",
        num_cars=2,
        sensors=("lidar",),
        action_space=SPACE,
        mode="training",
        seed=5,
    )
    env = RacingVecEnv(config, "follow_center_line", num_races=2, num_workers=workers)
    gen = torch.Generator().manual_seed(0)
    try:
        out = [(env.get_observations()["lidar"],)]
        for _ in range(steps):
            index = torch.randint(0, SPACE.n, (env.num_envs,), generator=gen)
            obs, rewards, dones, extras = env.step(torch.nn.functional.one_hot(index, SPACE.n))
            out.append((obs["lidar"], rewards, dones, extras["time_outs"]))
        return out, env.drain_simtrace()
    finally:
        env.close()


def _without_wall_clock(rows: list[dict]) -> list[dict]:
    """Rows minus ``wall_clock``, in ``(episode, steps)`` order (unique per car)."""
    rows = [{k: v for k, v in r.items() if k != "wall_clock"} for r in rows]
    return sorted(rows, key=lambda r: (int(r["episode"]), int(r["steps"])))


def test_workers_step_the_same_races_as_in_process():
    local, local_rows = _rollout(workers=0)
    spawned, spawned_rows = _rollout(workers=2)
    assert local[0][0].shape == (4, 64)  # 2 races x 2 cars; each lidar sees the other car
    assert float(local[0][0].min()) < 1.0
    for step, (a, b) in enumerate(zip(local, spawned, strict=True)):
        for x, y in zip(a, b, strict=True):
            assert torch.equal(x, y), step
    assert any(bool(s[2].any()) for s in local[1:])  # episodes ended and restarted
    assert len(local_rows) == 300 * 4
    assert _without_wall_clock(local_rows) == _without_wall_clock(spawned_rows)


def _settings(**kw) -> TrainSettings:
    base = {"action_space": SPACE, "sensors": ("lidar",), "races": 2, "eval_every": 1000}
    return TrainSettings(**{**base, **kw})


def _simtrace(run: Path) -> list[dict]:
    rows = []
    for path in sorted((run / "0" / "training-simtrace").glob("*-iteration.csv")):
        with path.open() as handle:
            rows += [{"file": path.name, **row} for row in csv.DictReader(handle)]
    return _without_wall_clock(rows)


@pytest.mark.slow
def test_training_with_workers_writes_the_in_process_simtrace(tmp_path):
    """Same seed, two PPO iterations: the training simtrace is the same row for row."""
    for workers in (0, 2):
        Trainer(_settings(workers=workers, iterations=2), tmp_path / str(workers), TINY).run()
    local, spawned = _simtrace(tmp_path / "0"), _simtrace(tmp_path / "2")
    assert {r["file"] for r in local} == {"0-iteration.csv", "1-iteration.csv"}
    assert local == spawned


def _evaluations(run: Path) -> tuple[list[dict], list[list[dict]]]:
    """The run's evaluation columns of ``metrics.csv``, and each evaluation's simtrace."""
    with (run / "metrics.csv").open() as handle:
        columns = [{k: v for k, v in r.items() if "eval" in k} for r in csv.DictReader(handle)]
    traces = []
    for path in sorted(run.glob("evaluation-*/evaluation-simtrace/0-iteration.csv")):
        with path.open() as handle:
            traces.append(_without_wall_clock(list(csv.DictReader(handle))))
    return columns, traces


@pytest.mark.slow
def test_evaluations_in_a_process_of_their_own_race_each_iteration_s_weights(tmp_path):
    """--background-eval: an evaluation races in a process of its own while the next
    iteration trains; it races the weights of the iteration it belongs to, as an evaluation
    in the trainer's process does, on every track with --eval-also-tracks, and its process
    ends with the run."""
    before = _workers(os.getpid())
    space = parse_action_space_spec("continuous:-30:30:0.5:2")  # any change of weights shows
    settings = {"action_space": space, "iterations": 3, "eval_every": 1, "eval_time_limit": 8.0}
    settings |= {"also_tracks": ("slipstream_speedway",), "eval_also_tracks": True}
    summaries = {}
    for background in (False, True):
        run = tmp_path / str(background)
        summaries[background] = seen = []
        Trainer(_settings(workers=2, background_eval=background, **settings), run, TINY).run(
            lambda stats, seen=seen: seen.append(stats.eval)
        )
    (local, local_traces) = _evaluations(tmp_path / "False")
    background = _evaluations(tmp_path / "True")
    assert all(row["eval_progress"] for row in local) and len(local) == 3
    assert len({str(trace) for trace in local_traces}) == 3  # each iteration drives its own way
    assert (local, local_traces) == background
    assert summaries[False] == summaries[True] and len(summaries[True]) == 3
    for evaluation in summaries[True]:  # beginner_loop, then the speedway: not the same race
        assert len(evaluation.races) == 2 and evaluation.also[0] != replace(evaluation, also=())
    for name in ("best", "last"):
        a, b = (torch.load(tmp_path / w / "checkpoints" / f"{name}.pt") for w in ("False", "True"))
        assert a["iteration"] == b["iteration"]
        for key, value in a["actor_state_dict"].items():
            assert torch.equal(value, b["actor_state_dict"][key]), (name, key)
    assert not _wait_gone(_workers(os.getpid()) - before, seconds=5.0)


# -------------------------------------------- 2. a reward failing in a worker
def test_a_reward_raising_in_a_worker_stops_the_cli_with_its_message(tmp_path):
    reward = tmp_path / "reward.py"
    reward.write_text(RAISING_REWARD)
    before = _workers(os.getpid())
    args = ["train", "--out", str(tmp_path / "run"), "--sensors", "lidar", "--iterations", "1"]
    args += ["--reward-fn", str(reward), "--workers", "2", "--races", "2"]
    result = CliRunner().invoke(app, args)
    output = "".join(result.output.split())  # rich wraps long lines, paths too

    def said(text: str) -> bool:
        return "".join(text.split()) in output

    assert result.exit_code == 2, result.output
    assert said("error: racing worker failed: race 0: reward function of car 'car0'")
    assert said(f"raised at step 9 ({reward}, line 4): ValueError")
    assert said("wheel sensor unplugged at step 9")
    assert not _wait_gone(_workers(os.getpid()) - before, seconds=5.0)


# ------------------------------------------------------- 3. Ctrl-C, workers on
@pytest.mark.slow
def test_ctrl_c_with_workers_saves_packs_and_stops_every_worker(tmp_path):
    run, hp = tmp_path / "run", tmp_path / "hp.json"
    hp.write_text(TINY.model_dump_json())
    command = [sys.executable, "-m", "slipstream", "train", "--out", str(run), "--minutes", "5"]
    command += ["--sensors", "lidar", "--action-space", "3x3@1.0", "--workers", "2"]
    command += ["--eval-every", "1", "--eval-time-limit", "60", "--background-eval"]
    command += ["--hyperparameters", str(hp)]
    env = {**os.environ, "COLUMNS": "200", "PYTHONFAULTHANDLER": "1"}
    # A session of its own: the process group a terminal's Ctrl-C signals. SIGINT as a
    # terminal leaves it: a shell's background job (`make test &`) ignores SIGINT, and an
    # ignored signal stays ignored in its children. (A launcher, not a preexec_fn: that
    # forks this threaded process, see tests/league/test_training_sandbox.py.)
    restore = "import os, signal, sys\nsignal.signal(signal.SIGINT, signal.SIG_DFL)\n"
    restore += "os.execv(sys.argv[1], sys.argv[1:])"
    proc = subprocess.Popen(
        [sys.executable, "-c", restore, *command], stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True, start_new_session=True, env=env,
    )  # fmt: skip
    try:
        metrics = run / "metrics.csv"
        deadline = time.monotonic() + 120
        while not (metrics.exists() and len(metrics.read_text().splitlines()) >= 2):
            assert proc.poll() is None and time.monotonic() < deadline, proc.stdout.read()
            time.sleep(0.1)
        workers = _workers(proc.pid)
        assert len(workers) == 3  # two env workers and the evaluations' process
        os.killpg(proc.pid, signal.SIGINT)
        try:
            output, _ = proc.communicate(timeout=120)
        except subprocess.TimeoutExpired:  # hung: faulthandler prints every thread's stack
            proc.send_signal(signal.SIGABRT)
            output, _ = proc.communicate(timeout=30)
            pytest.fail(f"the trainer outlived Ctrl-C by 120 s; its output and stacks:\n{output}")
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 0, output
    assert "stopped (Ctrl-C)" in output
    assert not _wait_gone(workers), "workers outlived the trainer"
    ckpt = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    assert ckpt["iteration"] >= 0 and "actor_state_dict" in ckpt
    assert validate(run / "model" / "model.zip").ok


# --------------------------------------------------------- 4. PFSP's weights
def test_pfsp_weights_are_the_documented_hard_weighting():
    # docs/training.md: weight (1 - p)^2 + 0.05 for win rate p, normalised.
    raw = np.array([0.8**2 + 0.05, 0.5**2 + 0.05, 0.1**2 + 0.05])  # 0.69, 0.30, 0.06
    np.testing.assert_allclose(pfsp_weights([0.2, 0.5, 0.9]), raw / raw.sum())
    np.testing.assert_allclose(raw / raw.sum(), [0.69 / 1.05, 0.30 / 1.05, 0.06 / 1.05])


def _pool(tmp_path: Path, seed: int) -> OpponentPool:
    """Two snapshots and a user policy, the learner winning 20%, 50% and 90% against them."""
    pool = OpponentPool(seed=seed)
    pool.add_snapshot("snapshot:0", b"graph 0")
    pool.add_snapshot("snapshot:9", b"graph 9")
    (tmp_path / "rival.onnx").write_bytes(b"rival")
    pool.add_policy(tmp_path / "rival.onnx")
    for name, rate in {"snapshot:0": 0.2, "snapshot:9": 0.5, "user:rival.onnx": 0.9}.items():
        pool.entries[name].win_rate = rate  # as if recorded (the moving average: below)
    return pool


def test_pool_records_outcomes_as_a_moving_average():
    pool = OpponentPool()
    pool.add_snapshot("a", b"a")
    assert pool.win_rates() == {"a": 0.5}  # unplayed
    pool.record("a", True)
    assert pool.win_rates()["a"] == pytest.approx(0.525)
    pool.record("a", False)
    assert pool.win_rates()["a"] == pytest.approx(0.525 * 0.95)
    for _ in range(98):
        pool.record("a", True)
    assert pool.win_rates()["a"] == pytest.approx(1.0 - (1.0 - 0.525 * 0.95) * 0.95**98)


def test_user_policies_of_the_same_file_name_each_keep_a_place(tmp_path):
    """Two runs' ``model.zip`` (the time-trial parent and the imitation run) both race."""
    pool = OpponentPool()
    for run in ("parent", "imitation"):
        (tmp_path / run).mkdir()
        with zipfile.ZipFile(tmp_path / run / "model.zip", "w") as archive:
            archive.writestr("policy.onnx", run.encode())
    names = [pool.add_policy(tmp_path / run / "model.zip") for run in ("parent", "imitation")]
    assert names == ["user:model.zip", "user:model.zip#2"]
    assert {o.graph for o in pool.sample(100)} == {b"parent", b"imitation"}


def test_pool_keeps_the_newest_8_snapshots_and_every_user_policy(tmp_path):
    (tmp_path / "rival.onnx").write_bytes(b"rival")
    pool = OpponentPool()
    pool.add_policy(tmp_path / "rival.onnx")
    for it in range(0, 100, 10):
        pool.add_snapshot(f"snapshot:{it}", b"graph")
    assert list(pool.win_rates()) == ["user:rival.onnx"] + [
        f"snapshot:{i}" for i in range(20, 100, 10)
    ]


def test_pool_draws_opponents_with_the_documented_probabilities(tmp_path):
    pool = _pool(tmp_path, seed=7)
    expected = {"snapshot:0": 0.69, "snapshot:9": 0.30, "user:rival.onnx": 0.06}
    expected = {name: weight / 1.05 for name, weight in expected.items()}
    assert pool.probabilities() == pytest.approx(expected)
    draws = 20_000
    picks = pool.sample(draws)
    assert {o.name: o.graph for o in picks} == {
        "snapshot:0": b"graph 0", "snapshot:9": b"graph 9", "user:rival.onnx": b"rival"
    }  # fmt: skip
    names = [o.name for o in picks]
    for name, p in expected.items():  # 4 standard deviations: below 0.014
        assert names.count(name) / draws == pytest.approx(p, abs=4 * (p * (1 - p) / draws) ** 0.5)
    again = _pool(tmp_path, seed=7)
    assert [o.name for o in again.sample(100)] == names[:100]  # a fixed seed draws the same


def test_paced_racers_join_the_draw_at_their_share_of_the_learners_pace():
    pool = OpponentPool(seed=1)
    pool.add_snapshot("snapshot:start", b"graph")
    for share in (0.6, 0.9, 1.0):
        pool.add_paced(share)
    # Until an evaluation gives the learner's pace, only the snapshot is drawn.
    assert list(pool.probabilities()) == ["snapshot:start"]
    assert {o.name for o in pool.sample(50)} == {"snapshot:start"}
    assert pool.table()[1] == {
        "opponent": "pursuit:60%", "games": 0, "win_rate": 0.5, "draw_probability": 0.0,
        "pace": None,
    }  # fmt: skip
    pool.set_pace(learner_lap_s=10.0, pursuit_lap_s=8.0)  # the learner at 80% of the driver
    assert list(pool.probabilities()) == [
        "snapshot:start",
        "pursuit:60%",
        "pursuit:90%",
        "pursuit:100%",
    ]
    paces = {o.name: o.pace for o in pool.sample(200) if o.pace is not None}
    assert paces == pytest.approx({"pursuit:60%": 0.48, "pursuit:90%": 0.72, "pursuit:100%": 0.8})
    assert [row["pace"] for row in pool.table()[1:]] == pytest.approx([0.48, 0.72, 0.8])
    assert sum(row["draw_probability"] for row in pool.table()) == pytest.approx(1.0)
    pool.set_pace(learner_lap_s=7.0, pursuit_lap_s=8.0)  # faster than the driver: capped
    paces = {o.name: o.pace for o in pool.sample(200) if o.pace is not None}
    assert paces["pursuit:100%"] == 1.0 and paces["pursuit:90%"] == 1.0
    assert paces["pursuit:60%"] == pytest.approx(0.6 * 8 / 7)
