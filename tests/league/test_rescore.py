"""``POST /api/rescore``: a logged run re-scored with an edited reward function, run in the
sandbox on the DeepRacer params rebuilt from a real race's trace or a training run's
simtrace."""

from __future__ import annotations

import csv
import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from agents.evaluate import write_evaluation
from arena.actions import default_discrete_space
from arena.config import NO_VARIATION, RaceConfig, resolve_track
from arena.drivers import LaneFollowerPolicy
from arena.env import RewardFunction
from arena.race import RaceResult, run_race
from arena.simtrace import race_rows, write_simtrace
from league.models import Event, TrainingJob
from league.training import rescore
from league.training.trainer import zip_folder
from submissions import pack
from tests.league.conftest import CREATED_AT, Database, League, policy_onnx, start_league
from tests.league.helpers import create_event, enter, record_as_worker

PROGRESS = "def reward_function(params):\n    return params['progress']\n"
DOUBLE = "def reward_function(params):\n    return 2.0 * params['progress']\n"


def _race(config: RaceConfig, reward: RewardFunction | None = None) -> RaceResult:
    """A real race of a lane follower in ``config``."""
    track, _ = resolve_track(config)
    car = config.cars[0]
    policy = LaneFollowerPolicy(track, car.action_space, speed=1.5)
    return run_race(config, {car.name: policy}, reward_functions=reward)


@dataclass
class Runs:
    """A stored race of alice's model (its archive holds :data:`DOUBLE`), and a finished
    training job of alice's with a real evaluation and training simtrace."""

    race_id: int
    car: str
    progress: list[float]
    job_id: int
    evaluation: list[dict[str, str]]
    episode: list[dict[str, str]]


def _upload_with_reward(league: League, folder: Path) -> int:
    folder.mkdir(parents=True, exist_ok=True)
    path = pack(
        folder / "rescored.zip",
        policy_onnx(3),
        default_discrete_space(),
        ["lidar"],
        reward_function=DOUBLE,
        created_at=CREATED_AT,
    )
    with league.client("alice") as client, path.open("rb") as handle:
        response = client.post("/api/models", files={"file": (path.name, handle)})
    assert response.status_code in (200, 201), response.text
    return response.json()["id"]


def _stored_race(league: League, folder: Path) -> tuple[int, str, list[float]]:
    event = create_event(league, name="Rescore Cup", laps=1, seeds=[0], time_limit_s=8.0)
    entry = enter(league, "alice", event["id"], _upload_with_reward(league, folder))
    with league.sessions() as session:
        ruleset = {**session.get_one(Event, event["id"]).ruleset, "variation": NO_VARIATION}
    result = _race(RaceConfig.build(**ruleset, cars=[{"name": "alice"}], seed=0))
    race_id = record_as_worker(league, event["id"], result, {"alice": entry["entry_id"]})
    return race_id, "alice", result.trace["alice"]["progress"]


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def _finished_job(league: League, folder: Path) -> tuple[int, list[dict], list[dict]]:
    """A done job whose stored run holds a real evaluation simtrace and one training
    iteration's simtrace (episode 4), rewarded by a reward of its own."""
    config = RaceConfig.build(
        track="beginner_loop", laps=1, time_limit_s=6.0, variation=NO_VARIATION, seed=1
    )
    result = _race(config, reward=lambda p: 1.0 + p["speed"])
    run = folder / "run"
    (run / "training_settings.json").parent.mkdir(parents=True, exist_ok=True)
    (run / "training_settings.json").write_text(json.dumps({"track": "beginner_loop"}))
    evaluation = write_evaluation(run, result) / "evaluation-simtrace" / "0-iteration.csv"
    name = config.cars[0].name
    training = run / "0" / "training-simtrace" / "0-iteration.csv"
    write_simtrace(training, race_rows(result, name, episode=4))
    sha, _ = league.storage.put("runs", zip_folder(run))
    with league.sessions() as session:
        job = TrainingJob(
            owner_id=league.ids["alice"],
            name="rescored-run",
            status="done",
            spec={"options": {"track": "beginner_loop"}},
            reward_source=PROGRESS,
            minutes=1.0,
            run_sha256=sha,
        )
        session.add(job)
        session.commit()
        return job.id, _rows(evaluation), _rows(training)


@pytest.fixture(scope="module")
def league(tmp_path_factory: pytest.TempPathFactory) -> Iterator[League]:
    """SQLite only: a re-score reads one row; what these tests exercise is the sandbox."""
    folder = tmp_path_factory.mktemp("rescore-league")
    database = Database(f"sqlite:///{folder / 'league.db'}", "sqlite")
    yield from start_league(database, folder / "data")


@pytest.fixture(scope="module")
def runs(league: League, tmp_path_factory: pytest.TempPathFactory) -> Runs:
    folder = tmp_path_factory.mktemp("rescore")
    race_id, car, progress = _stored_race(league, folder / "models")
    job_id, evaluation, episode = _finished_job(league, folder)
    return Runs(race_id, car, progress, job_id, evaluation, episode)


def _rescore(league: League, who: str = "bob", **body: object) -> dict:
    with league.client(who) as client:
        response = client.post("/api/rescore", json=body, timeout=90)
    return {"status": response.status_code, **response.json()}


def test_a_progress_reward_rescores_a_race_to_its_traces_progress(
    league: League, runs: Runs
) -> None:
    out = _rescore(league, reward_source=PROGRESS, race_id=runs.race_id, car=runs.car)
    assert out["status"] == 200, out
    assert out["steps"] == len(runs.progress) > 50
    assert out["reward"] == pytest.approx(runs.progress)
    assert out["progress"] == pytest.approx(runs.progress)
    assert len(out["x"]) == len(out["y"]) == len(out["lap"]) == out["steps"]
    assert out["total"] == pytest.approx(sum(runs.progress))
    # the model's archive holds its own reward function: it scores the same steps
    assert out["original"] == pytest.approx([2.0 * p for p in runs.progress])
    assert out["original_total"] == pytest.approx(2.0 * out["total"])
    assert sum(lap["reward"] for lap in out["laps"]) == pytest.approx(out["total"])


def test_a_reward_raising_at_line_3_is_refused_naming_it_and_the_step(
    league: League, runs: Runs
) -> None:
    source = (
        "def reward_function(params):\n"
        "    late = params['steps'] > 40\n"
        "    return params['speed'] / (0 if late else 1)\n"
    )
    out = _rescore(league, reward_source=source, race_id=runs.race_id, car=runs.car)
    assert out["status"] == 422
    assert "line 3" in out["detail"] and "at step 41" in out["detail"]
    assert "ZeroDivisionError" in out["detail"]


def test_a_reward_that_loops_forever_is_stopped_by_the_cpu_limit(
    league: League, runs: Runs, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(rescore, "RESCORE_CPU_SECONDS", 2)  # the server runs in this process
    source = "def reward_function(params):\n    while True:\n        pass\n"
    out = _rescore(league, reward_source=source, race_id=runs.race_id, car=runs.car)
    assert out["status"] == 422
    assert "CPU time" in out["detail"] and "loop forever" in out["detail"]


def test_a_training_runs_simtrace_rescores_with_its_logged_rewards(
    league: League, runs: Runs
) -> None:
    out = _rescore(league, "alice", reward_source=PROGRESS, training_job_id=runs.job_id)
    assert out["status"] == 200, out
    logged = [float(row["reward"]) for row in runs.evaluation]
    assert out["original"] == pytest.approx(logged)
    assert out["reward"] == pytest.approx([float(row["progress"]) for row in runs.evaluation])
    assert out["original_total"] == pytest.approx(sum(logged))
    episode = _rescore(
        league, "alice", reward_source=PROGRESS, training_job_id=runs.job_id, episode=4
    )
    assert episode["status"] == 200, episode
    assert episode["original"] == pytest.approx([float(row["reward"]) for row in runs.episode])


def test_only_the_owner_rescores_a_training_job(league: League, runs: Runs) -> None:
    out = _rescore(league, "bob", reward_source=PROGRESS, training_job_id=runs.job_id)
    assert out["status"] == 404
    assert _rescore(league, "bob", reward_source=PROGRESS, race_id=runs.race_id)["status"] == 422


@pytest.fixture
def _no_leftovers(league: League) -> Iterator[None]:
    yield
    assert not any((league.settings.data_dir / "training" / "rescores").iterdir())


def test_a_rescore_leaves_no_working_folder(
    _no_leftovers: None, league: League, runs: Runs
) -> None:
    out = _rescore(league, reward_source="x = (", race_id=runs.race_id, car=runs.car)
    assert out["status"] == 422 and "syntax error at line 1" in out["detail"]
