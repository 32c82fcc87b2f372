"""Training jobs through the API: the up-front check (a broken reward names its line), a
reward function's escapes refused by the sandbox with the league intact, quotas, stop,
priorities; on SQLite and PostgreSQL against a real server."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator

import pytest
from sqlalchemy import func, select

from league.models import Model, Racer, TrainingJob
from league.training.queue import add_event
from league.training.sandbox import probe
from tests.league.conftest import Database, League, start_league

pytestmark = pytest.mark.skipif(
    probe() is not None and os.environ.get("CI") != "true",
    reason=f"this host cannot sandbox training jobs: {probe()} (CI installs bubblewrap)",
)

GOOD_REWARD = "def reward_function(params):\n    return float(params['progress']) + 1.0\n"
OPTIONS = {"track": "slipstream_speedway", "sensors": "camera", "action_space": "default"}


@pytest.fixture(scope="module")
def league(database: Database, tmp_path_factory: pytest.TempPathFactory) -> Iterator[League]:
    """A league whose quotas are small enough to reach in a test."""
    yield from start_league(
        database,
        tmp_path_factory.mktemp("league") / "data",
        training_max_minutes=30,
        training_queued_per_racer=3,
        training_minutes_per_month=80,
    )


def _body(reward: str = GOOD_REWARD, minutes: float = 1, **changes: object) -> dict:
    return {
        "name": "car",
        "reward_source": reward,
        "options": OPTIONS,
        "minutes": minutes,
    } | changes


def _clear(league: League) -> None:
    with league.sessions() as session:
        session.query(TrainingJob).delete()
        session.commit()


def test_a_valid_job_is_queued_and_its_owner_reads_it(league: League) -> None:
    _clear(league)
    with league.client("alice") as alice, league.client("bob") as bob:
        created = alice.post("/api/training-jobs", json=_body())
        assert created.status_code == 201, created.text
        job = created.json()
        assert job["status"] == "queued" and job["owner"] == "alice"
        assert job["options"] == OPTIONS and job["minutes"] == 1
        assert job["description"] is None and job["race_settings"] == {}
        bots = {"race_type": "head_to_bot", "bots": 2, "bot_speed": 1.2}
        described = _body(options={**OPTIONS, **bots}, description="two quick bots")
        second = alice.post("/api/training-jobs", json=described).json()
        assert second["description"] == "two quick bots"
        assert second["race_settings"] == {"bots": 2, "bot_speed": 1.2}
        listed = [j["id"] for j in alice.get("/api/training-jobs").json()]
        assert listed == [second["id"], job["id"]]
        assert bob.get(f"/api/training-jobs/{job['id']}").status_code == 404
        assert bob.get("/api/training-jobs").json() == []


@pytest.mark.parametrize(
    ("reward", "expected"),
    [
        ("def reward_function(params):\n    x = 1\n    return missing_name\n", "line 3"),
        ("def reward_function(params)\n    return 1.0\n", "syntax error at line 1"),
        ("def reward_function(params):\n    return float('nan')\n", "nan"),
        ("x = 1\n", "does not define reward_function"),
    ],
)
def test_a_broken_reward_is_refused_naming_what_is_wrong(
    league: League, reward: str, expected: str
) -> None:
    with league.client("alice") as alice:
        answer = alice.post("/api/training-jobs", json=_body(reward))
    assert answer.status_code == 422, answer.text
    detail = answer.json()["detail"]
    assert expected in detail and detail.startswith("reward.py")
    assert str(league.settings.data_dir) not in detail


def test_validate_checks_a_job_without_queuing_it(league: League) -> None:
    _clear(league)
    broken = "def reward_function(params):\n    return params['no_such_key']\n"
    with league.client("alice") as alice:
        assert alice.post("/api/training-jobs/check", json=_body()).json() == {"ok": True}
        anchored = _body(
            options={
                "anchor": "pursuit",
                "anchor_weight": 0.5,
                "critic_warmup": 3,
                "also_tracks": "grand_tour",
            }
        )
        assert alice.post("/api/training-jobs/check", json=anchored).json() == {"ok": True}
        refused = alice.post("/api/training-jobs/check", json=_body(broken))
        assert refused.status_code == 422 and "at line 2" in refused.json()["detail"]
        assert alice.get("/api/training-jobs").json() == []


@pytest.mark.parametrize(
    ("options", "expected"),
    [
        ({"track": "no_such_track"}, "built-in tracks"),
        ({"also_tracks": "grand_tour,/tmp/my_track.csv"}, "built-in tracks"),
        ({"action_space": "/etc/passwd"}, "not a file"),
        ({"workers": 16}, "cannot set workers"),
        ({"reward_fn": "/etc/shadow"}, "cannot set reward_fn"),
        ({"sensors": "radar"}, "radar"),
        ({"race_type": "time_trial", "boxes": 3}, "boxes: only object_avoidance races"),
        ({"race_type": "head_to_bot", "bots": 9}, "bots: Input should be less than or equal"),
        ({"teacher": "pursuit", "anchor": "pursuit"}, "--anchor holds PPO near a driver"),
    ],
)
def test_settings_a_job_may_not_have_are_refused_before_any_code_runs(
    league: League, options: dict, expected: str
) -> None:
    with league.client("alice") as alice:
        answer = alice.post("/api/training-jobs", json=_body(options=options))
    assert answer.status_code == 422 and expected in answer.json()["detail"], answer.text


def _escape(league: League, reward: str) -> str:
    """Submit a reward that tries an escape while it is checked; the 422 detail."""
    with league.client("bob") as bob:
        answer = bob.post("/api/training-jobs", json=_body(reward))
    assert answer.status_code == 422, answer.text
    return answer.json()["detail"]


def _league_intact(league: League) -> None:
    with league.client("alice") as alice:
        assert alice.get("/api/racers/me").json()["alias"] == "alice"
    with league.sessions() as session:
        assert session.scalar(select(func.count()).select_from(Racer)) == 3
        assert session.scalar(select(func.count()).select_from(Model)) == 0


def test_a_reward_cannot_reach_the_network(league: League) -> None:
    reward = (
        "import socket\n"
        "def reward_function(params):\n"
        "    socket.create_connection(('127.0.0.1', 5432), timeout=2)\n"
        "    return 1.0\n"
    )
    detail = _escape(league, reward)
    assert "ConnectionRefusedError" in detail or "unreachable" in detail
    _league_intact(league)


def test_a_reward_cannot_read_the_database_or_the_data_dir(league: League) -> None:
    target = league.settings.data_dir / "league.db"
    if league.backend == "postgres":
        target = league.settings.data_dir / "files"
        target.mkdir(parents=True, exist_ok=True)
    reward = (
        "import os\n"
        "def reward_function(params):\n"
        f"    os.listdir({str(target)!r}) if os.path.isdir({str(target)!r}) "
        f"else open({str(target)!r}, 'rb').read(16)\n"
        "    return 1.0\n"
    )
    assert "FileNotFoundError" in _escape(league, reward)
    _league_intact(league)


def test_a_reward_sees_no_secret_of_the_server(
    league: League, monkeypatch: pytest.MonkeyPatch
) -> None:
    secret = "s3cr3t-token-of-the-league"
    monkeypatch.setenv("SLIPSTREAM_S3_SECRET", secret)
    reward = (
        "import os\n"
        "def reward_function(params):\n"
        "    seen = repr(dict(os.environ))\n"
        "    for name in ('/proc/1/environ', '/proc/self/environ', '/proc/2/environ'):\n"
        "        try:\n"
        "            seen += open(name).read()\n"
        "        except OSError as exc:\n"
        "            seen += str(exc)\n"
        "    raise ValueError(seen)\n"
    )
    detail = _escape(league, reward)
    assert "ValueError" in detail and secret not in detail
    assert "SLIPSTREAM" not in detail


def test_a_fork_bomb_in_a_reward_is_stopped(league: League) -> None:
    reward = (
        "import os, time\n"
        "def reward_function(params):\n"
        "    for _ in range(5000):\n"
        "        if os.fork() == 0:\n"
        "            time.sleep(5)\n"
        "            os._exit(0)\n"
        "    return 1.0\n"
    )
    detail = _escape(league, reward)
    assert "Resource temporarily unavailable" in detail or "BlockingIOError" in detail
    _league_intact(league)


def test_a_reward_cannot_take_50_gb_of_memory(league: League) -> None:
    reward = "def reward_function(params):\n    bytearray(50 * 1024**3)\n    return 1.0\n"
    assert "MemoryError" in _escape(league, reward)
    _league_intact(league)


def test_a_reward_cannot_write_10_gb(league: League) -> None:
    reward = (
        "def reward_function(params):\n"
        "    with open('big.bin', 'wb') as f:\n"
        "        for _ in range(10 * 1024):\n"
        "            f.write(b'x' * 1024 * 1024)\n"
        "    return 1.0\n"
    )
    assert "File too large" in _escape(league, reward)
    checks = league.settings.data_dir / "training" / "checks"
    assert not checks.exists() or not any(checks.iterdir())  # the check's folder is gone
    _league_intact(league)


def test_quotas_refuse_with_which_quota_and_when_it_resets(league: League) -> None:
    _clear(league)
    with league.client("alice") as alice:
        long = alice.post("/api/training-jobs", json=_body(minutes=31))
        assert long.status_code == 422 and "training_max_minutes" in long.json()["detail"]
        for _ in range(2):
            assert alice.post("/api/training-jobs", json=_body(minutes=30)).status_code == 201
        over = alice.post("/api/training-jobs", json=_body(minutes=30))  # 90 of 80 minutes
        assert over.status_code == 429
        assert "monthly training quota" in over.json()["detail"]
        assert "resets on" in over.json()["detail"] and int(over.headers["retry-after"]) > 0
        assert alice.post("/api/training-jobs", json=_body(minutes=20)).status_code == 201
        fourth = alice.post("/api/training-jobs", json=_body(minutes=1))
        assert fourth.status_code == 429 and "training_queued_per_racer" in fourth.json()["detail"]
        assert alice.get("/api/training-jobs/quota").json()["minutes_used"] == 80
        first = alice.get("/api/training-jobs").json()[-1]
        assert alice.post(f"/api/training-jobs/{first['id']}/stop").json()["status"] == "stopped"
        assert alice.get("/api/training-jobs/quota").json()["minutes_used"] == 50
        again = alice.post("/api/training-jobs", json=_body(minutes=30))
        assert again.status_code == 201, again.text


def test_only_an_admin_reprioritises(league: League) -> None:
    _clear(league)
    with league.client("alice") as alice, league.client("admin") as admin:
        job = alice.post("/api/training-jobs", json=_body()).json()
        url = f"/api/training-jobs/{job['id']}"
        assert alice.patch(url, json={"priority": 5}).status_code == 403
        assert admin.patch(url, json={"priority": 5}).json()["priority"] == 5
        assert [j["id"] for j in admin.get("/api/training-jobs").json()] == [job["id"]]


def _stream(league: League, job_id: int, last_event_id: int = 0) -> list[tuple[int, str]]:
    """Read a job's event stream to its end: (id, event) pairs."""
    headers = {"Last-Event-ID": str(last_event_id)} if last_event_id else {}
    seen: list[tuple[int, str]] = []
    with league.client("alice") as alice:
        url = f"/api/training-jobs/{job_id}/events"
        with alice.stream("GET", url, headers=headers, timeout=60) as answer:
            assert answer.status_code == 200
            assert answer.headers["content-type"].startswith("text/event-stream")
            event_id = None
            for line in answer.iter_lines():
                if line.startswith("id: "):
                    event_id = int(line[4:])
                elif line.startswith("event: "):
                    seen.append((event_id, line[7:]))
    return seen


def test_viewers_share_the_live_events_and_resume_where_they_left(league: League) -> None:
    _clear(league)
    with league.client("alice") as alice:
        job_id = alice.post("/api/training-jobs", json=_body()).json()["id"]
    with league.sessions() as session:
        add_event(session, job_id, "log", {"line": "before anyone watched"})
        session.commit()
    results: list[list[tuple[int, str]]] = [[] for _ in range(4)]

    def watch(index: int) -> None:
        results[index] = _stream(league, job_id)

    viewers = [threading.Thread(target=watch, args=(i,)) for i in range(4)]
    for viewer in viewers:
        viewer.start()
    time.sleep(1.0)
    with league.sessions() as session:
        for iteration in range(3):
            add_event(session, job_id, "iteration", {"iteration": iteration})
            session.commit()
            time.sleep(0.3)
        job = session.get_one(TrainingJob, job_id)
        job.status = "done"
        add_event(session, job_id, "status", {"status": "done", "error": None})
        session.commit()
    for viewer in viewers:
        viewer.join(60)
    kinds = ["log", "iteration", "iteration", "iteration", "status"]
    for seen in results:
        assert [kind for _id, kind in seen] == kinds
    assert len({tuple(seen) for seen in results}) == 1  # every viewer saw the same events
    second = results[0][1][0]
    assert [kind for _id, kind in _stream(league, job_id, second)] == kinds[2:]
