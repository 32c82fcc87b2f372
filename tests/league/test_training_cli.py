"""``slipstream league train``, ``jobs`` and ``stop-training`` against a real server, and
the client's reading of a training job's Server-Sent Events; on SQLite and PostgreSQL."""

from __future__ import annotations

import asyncio
import re
from collections.abc import Iterator
from pathlib import Path

import pytest
import typer
from sqlalchemy import event, func, select
from sqlalchemy.orm import ORMExecuteState, Session
from typer.testing import CliRunner

from league.cli import _follow, app
from league.client import LeagueClient, LeagueError, _server_sent_events
from league.http.training_feed import TrainingFeed
from league.models import TrainingJob, utcnow
from league.training.queue import add_event
from league.training.sandbox import probe
from tests.league.conftest import Database, League, start_league

runner = CliRunner()
MAX_MINUTES = 30


@pytest.fixture(scope="module")
def league(database: Database, tmp_path_factory: pytest.TempPathFactory) -> Iterator[League]:
    """A league whose longest training job is ``MAX_MINUTES``. These tests are about the
    command line, not the sandbox (tests/league/test_training_jobs.py): on a host that
    cannot sandbox, the server checks reward functions unconfined rather than answer 503."""
    yield from start_league(
        database,
        tmp_path_factory.mktemp("league") / "data",
        training_max_minutes=MAX_MINUTES,
        training_minutes_per_month=100,
        training_unconfined=probe() is not None,
    )


def _run(league: League, who: str, *args: str) -> tuple[int, str]:
    """Run ``slipstream league ARGS`` as ``who``: the exit code and the output, its
    whitespace collapsed (Rich wraps long lines)."""
    command = [*args, "--server", league.url, "--token", league.tokens[who]]
    result = runner.invoke(app, command, env={"COLUMNS": "200"})
    return result.exit_code, " ".join(result.output.split())


def _train(league: League, who: str, *args: str) -> tuple[int, str]:
    return _run(league, who, "train", "--name", "cli-car", "--track", "slipstream_speedway", *args)


def _job_count(league: League, who: str) -> int:
    with league.sessions() as session:
        query = select(func.count()).select_from(TrainingJob)
        return session.scalar(query.where(TrainingJob.owner_id == league.ids[who]))


def test_a_broken_reward_is_refused_naming_its_line(league: League, tmp_path: Path) -> None:
    reward = tmp_path / "reward.py"
    reward.write_text("def reward_function(params):\n    x = 1\n    return missing_name\n")
    before = _job_count(league, "alice")
    code, out = _train(league, "alice", "--reward-fn", str(reward), "--minutes", "1")
    assert code == 1, out
    assert "the server refused" in out and "line 3" in out and "missing_name" in out
    assert _job_count(league, "alice") == before


def test_a_job_is_queued_listed_with_the_quota_and_stopped(league: League) -> None:
    code, out = _train(league, "alice", "--reward-fn", "follow_center_line", "--minutes", "1")
    assert code == 0, out
    match = re.search(r"training job (\d+) \(cli-car\): queued", out)
    assert match, out
    job_id = int(match.group(1))
    with league.sessions() as session:
        job = session.get_one(TrainingJob, job_id)
        assert job.spec["options"] == {"track": "slipstream_speedway"}
        assert "def reward_function" in job.reward_source

    code, out = _run(league, "alice", "jobs")
    assert code == 0, out
    assert re.search(rf"\b{job_id} cli-car queued 1 0\.0 - - 20\d\d-", out), out
    assert "training quota: 1.0 of 100 minutes used this month" in out

    code, out = _run(league, "alice", "stop-training", str(job_id))
    assert code == 0 and f"training job {job_id}: stopped" in out, out
    with league.client("alice") as alice:
        assert alice.get(f"/api/training-jobs/{job_id}").json()["status"] == "stopped"
    code, out = _run(league, "alice", "jobs")
    assert re.search(rf"\b{job_id} cli-car stopped 1 ", out), out
    code, out = _run(league, "bob", "stop-training", str(job_id))
    assert code == 1 and "not found among your jobs" in out


def test_missing_files_are_refused_before_any_request(league: League, tmp_path: Path) -> None:
    before = _job_count(league, "bob")
    missing = tmp_path / "nowhere" / "hyperparameters.json"
    code, out = _train(league, "bob", "--minutes", "1", "--hyperparameters", str(missing))
    assert code == 2 and "--hyperparameters" in out and "does not exist" in out, out
    code, out = _train(league, "bob", "--minutes", "1", "--reward-fn", str(tmp_path / "r.py"))
    assert code == 2 and "--reward-fn" in out and "no such file" in out, out
    code, out = _train(league, "bob", "--minutes", "1", "--reward-fn", "no_such_sample")
    assert code == 2 and "follow_center_line" in out, out
    assert _job_count(league, "bob") == before


def test_a_budget_over_the_league_maximum_gets_the_servers_message(league: League) -> None:
    before = _job_count(league, "bob")
    code, out = _train(league, "bob", "--minutes", str(MAX_MINUTES + 15))
    assert code == 1, out
    assert f"at most {MAX_MINUTES} minutes" in out and "training_max_minutes" in out
    assert _job_count(league, "bob") == before


def _job(league: League, status: str, who: str = "bob", **fields: object) -> int:
    """A training job straight in the database (no reward check, no trainer)."""
    with league.sessions() as session:
        job = TrainingJob(
            owner_id=league.ids[who],
            name="streamed",
            spec={"options": {}, "recipe": None, "hyperparameters": None, "minutes": 1},
            reward_source="def reward_function(params):\n    return 1.0\n",
            minutes=1,
            status=status,
            **fields,
        )
        session.add(job)
        session.commit()
        return job.id


def test_a_racer_over_the_queued_jobs_quota_is_told_when_to_retry(league: League) -> None:
    for _ in range(league.settings.training_queued_per_racer):
        _job(league, "queued", who="admin")
    code, out = _train(league, "admin", "--minutes", "1")
    assert code == 1, out
    assert "training_queued_per_racer" in out and "try again in 60 s" in out


def _add(league: League, job_id: int, events: list[tuple[str, dict]], status: str = "") -> None:
    with league.sessions() as session:
        for kind, data in events:
            add_event(session, job_id, kind, data)
        if status:
            job = session.get_one(TrainingJob, job_id)
            job.status, job.finished_at = status, utcnow()
        session.commit()


ITERATION = {"iteration": 1, "mean_reward": 12.5, "mean_progress": 40.0, "eval": None}
EVALUATED = {
    "iteration": 2,
    "mean_reward": 30.25,
    "mean_progress": 75.0,
    "eval": {"laps": 2, "best_lap": 11.5, "progress": 100.0, "off_track": 0},
}
EVENTS = [
    ("status", {"status": "running", "trainer": "t1"}),
    ("log", {"line": "training starts: data: {not json} \u00e9"}),
    ("iteration", ITERATION),
    ("iteration", EVALUATED),
    ("status", {"status": "done", "error": None}),
]


def test_the_client_reads_a_jobs_events_in_order_and_resumes(
    league: League, tmp_path: Path
) -> None:
    job_id = _job(league, "running", started_at=utcnow())
    _add(league, job_id, EVENTS[:2])
    with LeagueClient(league.url, league.tokens["bob"]) as client:
        stream = client.training_events(job_id)
        assert next(stream) == EVENTS[0]
        assert next(stream) == EVENTS[1]
        _add(league, job_id, EVENTS[2:], status="done")  # while the stream is open
        assert list(stream) == EVENTS[2:]  # and it ends: the job has ended

        ids = [row["id"] for row in client.training_metrics(job_id)]
        assert [row["iteration"] for row in client.training_metrics(job_id)] == [1, 2]
        assert list(client.training_events(job_id, last_event_id=ids[0])) == EVENTS[3:]
        assert "training starts" in client.training_logs(job_id)

        with league.sessions() as session:
            job = session.get_one(TrainingJob, job_id)
            job.run_sha256 = league.storage.put("runs", b"PK run folder")[0]
            session.commit()
        saved = client.download_run(job_id, tmp_path / "run.zip")
        assert saved.read_bytes() == b"PK run folder"
        with pytest.raises(LeagueError, match="no stored run"):
            client.download_run(_job(league, "queued"), tmp_path / "none.zip")
        assert not (tmp_path / "none.zip").exists()
    with (
        LeagueClient(league.url, league.tokens["alice"]) as client,
        pytest.raises(LeagueError, match="not found among your jobs"),
    ):
        next(client.training_events(job_id))


def test_a_job_that_ends_while_the_feed_reads_it_still_streams_its_last_events(
    league: League,
) -> None:
    """The feed's poll reads a job's events and its status in two statements; a trainer
    that reports its last events and ends between the two loses no event."""
    job_id = _job(league, "running", started_at=utcnow())
    _add(league, job_id, EVENTS[:2])
    ended_between = []

    def end_after_first_statement(state: ORMExecuteState) -> object:
        frozen = state.invoke_statement().freeze()
        if not ended_between:
            ended_between.append(True)
            _add(league, job_id, EVENTS[2:], status="done")
        return frozen()

    def sessions() -> Session:
        session = league.sessions()
        event.listen(session, "do_orm_execute", end_after_first_statement)
        return session

    async def follow() -> list[tuple[str, dict]]:
        return [(e.kind, e.data) async for e in TrainingFeed(sessions).follow(job_id, 0)]

    assert asyncio.run(asyncio.wait_for(follow(), 30)) == EVENTS
    assert ended_between


def test_following_a_job_prints_its_iterations_and_how_it_ended(
    league: League, capsys: pytest.CaptureFixture[str]
) -> None:
    done = _job(league, "running", best_lap_ms=11500)
    _add(league, done, EVENTS, status="done")
    failed = _job(league, "running", error="the reward function raised at line 7")
    _add(league, failed, [("iteration", ITERATION)], status="failed")
    with LeagueClient(league.url, league.tokens["bob"]) as client:
        _follow(client, done)
        printed = " ".join(capsys.readouterr().out.split())
        assert "it 1 reward 12.5 progress 40%" in printed
        assert "it 2 reward 30.2 progress 75% eval 2 laps, best lap 11.500 s" in printed
        assert "training starts: data: {not json}" in printed
        assert "done: no model, best lap 11.500 s" in printed
        with pytest.raises(typer.Exit) as ended:
            _follow(client, failed)
    assert ended.value.exit_code == 1
    assert "failed: the reward function raised at line 7" in capsys.readouterr().out


def test_server_sent_events_are_parsed_as_the_standard_says() -> None:
    lines = [
        ": waiting",
        "id: 7",
        "event: log",
        'data: {"line":',
        'data: "two lines"}',
        "",
        "",
        "data:[1, 2]",
        "",
        "id: 9",
        "event: status",
        "data: not json",
        "",
        "event: log",  # no blank line after it: an unfinished event is dropped
        'data: {"line": "cut"}',
    ]
    assert list(_server_sent_events(iter(lines))) == [
        (7, "log", {"line": "two lines"}),
        (7, "message", {"value": [1, 2]}),
        (9, "status", {"text": "not json"}),
    ]
