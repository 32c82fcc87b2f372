"""The training page in real Chromium: the reward graph and the live view from a job's
events (as a trainer writes them; no training here), the warning when evaluation laps get
slower while the reward rises, a running job's graph growing as events arrive, and choosing
another checkpoint of a stored run as the model to evaluate and submit."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from sqlalchemy import select

from league.models import Entry, Event, TrainingEvent, TrainingJob, utcnow
from tests.league.conftest import League, make_model_zip
from tests.league.test_checkpoints import KEPT, checkpoint_index, run_zip
from tests.web.test_browser import sign_in
from tests.web.test_csp import violations, watch_csp

SPEC = {"options": {"track": "slipstream_speedway"}, "recipe": None, "hyperparameters": None}


def _iteration(i: int, reward: float, lap: float | None = None) -> dict[str, Any]:
    record: dict[str, Any] = {
        "iteration": i, "elapsed_s": 6.0 * i, "steps": 640, "episodes": 4,
        "mean_reward": reward, "mean_progress": min(100.0, 10.0 * i), "lap_completion": 0.5,
        "value_loss": 0.1, "surrogate_loss": 0.0, "entropy": 1.0, "eval": None,
    }  # fmt: skip
    if lap is not None:
        record["eval"] = {
            "laps": 3, "progress": 100.0, "best_lap": lap, "total_time": 3 * lap,
            "off_track": 0, "crashes": 0, "resets": 0, "status": "finished",
        }  # fmt: skip
    return record


def _job(
    league: League, status: str, events: list[tuple[str, dict]], spec: dict | None = None
) -> int:
    with league.sessions() as session:
        job = TrainingJob(
            owner_id=league.ids["alice"], name=f"page-{status}", status=status, spec=spec or SPEC,
            reward_source="def reward_function(params):\n    return 1.0\n", minutes=5,
            started_at=utcnow(), finished_at=utcnow() if status == "done" else None,
        )  # fmt: skip
        session.add(job)
        session.flush()
        session.add_all(TrainingEvent(job_id=job.id, kind=k, data=d) for k, d in events)
        session.commit()
        return job.id


def _add(league: League, job_id: int, kind: str, data: dict) -> None:
    with league.sessions() as session:
        session.add(TrainingEvent(job_id=job_id, kind=kind, data=data))
        session.commit()


def test_a_finished_job_draws_its_graph_view_evaluations_and_the_lap_warning(
    page, league: League
) -> None:
    # The measured case: the best lap early, slower ever since, the reward still climbing.
    laps = {3: 7.2, 6: 8.4, 9: 9.9, 12: 11.8}
    events = [("iteration", _iteration(i, 10.0 * i, laps.get(i))) for i in range(1, 13)]
    poses = {"iteration": 12, "episode": "3", "x": [0.0, 0.5, 1.0], "y": [0.0, 0.0, 0.1]}
    events.append(("poses", {**poses, "yaw": [0.0, 0.0, 5.0]}))
    events.append(("status", {"status": "done", "error": None}))
    job_id = _job(league, "done", events)
    console = watch_csp(page)
    sign_in(page, league, "alice")
    page.goto(f"/garage/jobs/{job_id}")
    page.wait_for_selector("#reward-graph[data-points='12']")
    page.wait_for_selector("#live-view[data-poses='3']")
    assert page.get_attribute("#status", "data-status") == "done"
    rows = page.eval_on_selector_all(
        "#eval-laps tbody tr", "rs => rs.map(r => r.cells[3].innerText)"
    )
    assert rows == ["0:07.200", "0:08.400", "0:09.900", "0:11.800"]
    warning = page.inner_text("#warning")
    assert "slower for 3 evaluations" in warning and "7.20 s" in warning and "11.80 s" in warning
    assert violations(page, console) == []


def test_no_warning_while_laps_improve(page, league: League) -> None:
    laps = {3: 11.0, 6: 10.0, 9: 9.0, 12: 8.0}
    job_id = _job(
        league, "done", [("iteration", _iteration(i, 5.0 * i, laps.get(i))) for i in range(1, 13)]
    )
    sign_in(page, league, "alice")
    page.goto(f"/garage/jobs/{job_id}")
    page.wait_for_selector("#reward-graph[data-points='12']")
    assert page.is_hidden("#warning")


def test_a_running_jobs_graph_grows_as_its_trainer_reports(page, league: League) -> None:
    job_id = _job(league, "running", [("iteration", _iteration(i, float(i))) for i in range(1, 4)])
    sign_in(page, league, "alice")
    page.goto(f"/garage/jobs/{job_id}")
    page.wait_for_selector("#reward-graph[data-points='3']")
    _add(league, job_id, "iteration", _iteration(4, 4.0))
    _add(league, job_id, "log", {"line": "iteration 4 done"})
    page.wait_for_selector("#reward-graph[data-points='4']")
    page.wait_for_function(
        "() => document.getElementById('log').textContent.includes('iteration 4')"
    )
    with league.sessions() as session:
        job = session.get_one(TrainingJob, job_id)
        job.status, job.finished_at = "stopped", utcnow()
        session.add(TrainingEvent(job_id=job_id, kind="status", data={"status": "stopped"}))
        session.commit()
    page.wait_for_selector("#status[data-status=stopped]")
    assert page.is_hidden("#stop")


def _job_with_run(
    league: League, archives: dict[str, bytes], spec: dict | None = None
) -> tuple[int, dict]:
    """A done job whose stored run holds ``archives`` (checkpoint -> archive) as a job's
    child packs them, its own model the ``best`` one; the job's id and that model."""
    members = {"models/index.json": checkpoint_index(KEPT)}
    members |= {f"models/{name}.zip": data for name, data in archives.items()}
    with league.client("alice") as alice:
        best = alice.post("/api/models", files={"file": ("best.zip", archives["best"])}).json()
    sha, _ = league.storage.put("runs", run_zip(members))
    job_id = _job(league, "done", [("status", {"status": "done", "error": None})], spec=spec)
    with league.sessions() as session:
        job = session.get_one(TrainingJob, job_id)
        job.model_id, job.run_sha256 = best["id"], sha
        session.commit()
    return job_id, best


def test_a_checkpoint_other_than_the_best_becomes_the_model_evaluated_and_submitted(
    page, league: League, tmp_path: Path
) -> None:
    archives = {c.name: make_model_zip(tmp_path, 40 + i).read_bytes() for i, c in enumerate(KEPT)}
    spec = {**SPEC, "options": {"race_type": "head_to_bot", "bots": 2}, "description": "bots"}
    job_id, best = _job_with_run(league, archives, spec)

    console = watch_csp(page)
    sign_in(page, league, "alice")
    page.goto(f"/garage/jobs/{job_id}")
    page.wait_for_selector("#checkpoints tr[data-checkpoint=fastest]")
    assert page.inner_text("#job-description") == "bots"
    assert "head to bot (bots 2)" in page.inner_text("#job-facts")
    laps = page.eval_on_selector_all(
        "#checkpoints tbody tr", "rs => rs.map(r => r.cells[4].innerText)"
    )
    assert laps == ["0:12.400", "0:10.800", "—"]
    assert page.is_checked("#checkpoint-best")  # the job's own model
    assert page.get_attribute("#model-link a", "href") == f"/models/{best['id']}"

    page.check("#checkpoint-fastest")
    page.click("#use-checkpoint")
    page.wait_for_selector("#checkpoint-result.ok")
    with league.client("alice") as alice:
        fastest = next(m for m in alice.get("/api/models").json() if m["name"].endswith("fastest"))
    assert page.get_attribute("#model-link a", "href") == f"/models/{fastest['id']}"
    page.wait_for_selector(
        f"#checkpoints tr[data-checkpoint=fastest] a[href='/models/{fastest['id']}']"
    )
    assert page.is_checked("#checkpoint-fastest")

    # Evaluated, the chosen model races its job's race type with the job's own bots.
    page.wait_for_selector(
        "#evaluate-track option[value='slipstream_speedway'], #evaluate-result.error",
        state="attached",
    )
    assert page.query_selector("#evaluate-result.error") is None, page.inner_text(
        "#evaluate-result"
    )
    page.click("#evaluate")
    page.wait_for_selector("#evaluate-result.ok, #evaluate-result.error")
    assert "Queued" in page.inner_text("#evaluate-result"), page.inner_text("#evaluate-result")
    with league.sessions() as session:
        event = session.scalars(select(Event).where(Event.kind == "evaluation")).all()[-1]
        entered = session.scalar(select(Entry.model_id).where(Entry.event_id == event.id))
        assert (event.race_type, event.ruleset["bots"]["count"]) == ("head_to_bot", 2)
        assert entered == fastest["id"]
    assert violations(page, console) == []


def test_checkpoints_of_one_iteration_show_their_shared_model_chosen_once(
    page, league: League, tmp_path: Path
) -> None:
    """The best and the fastest evaluation were the same one: one archive, one model."""
    archives = {c.name: make_model_zip(tmp_path, 50 + i).read_bytes() for i, c in enumerate(KEPT)}
    archives["fastest"] = archives["best"]
    job_id, best = _job_with_run(league, archives)
    sign_in(page, league, "alice")
    page.goto(f"/garage/jobs/{job_id}")
    page.wait_for_selector("#checkpoints tr[data-checkpoint=fastest]")
    for name in ("best", "fastest"):
        link = page.get_attribute(f"#checkpoints tr[data-checkpoint={name}] a", "href")
        assert link == f"/models/{best['id']}"
    assert page.is_checked("#checkpoint-best") and not page.is_checked("#checkpoint-fastest")


def test_the_track_and_event_lists_load_after_a_failed_fetch_and_say_when_they_cannot(
    page, league: League, tmp_path: Path
) -> None:
    """One dropped connection or busy answer is tried again; a server that never answers the
    catalogue leaves a message, not an empty list that cannot be evaluated."""
    archives = {c.name: make_model_zip(tmp_path, 60 + i).read_bytes() for i, c in enumerate(KEPT)}
    job_id, _ = _job_with_run(league, archives)
    sign_in(page, league, "alice")
    failed: list[str] = []

    def first_fails(route) -> None:
        if route.request.url in failed:
            route.continue_()
        else:
            failed.append(route.request.url)
            route.abort() if "catalogue" in route.request.url else route.fulfill(status=503)

    page.route("**/api/garage/catalogue", first_fails)
    page.route("**/api/events", first_fails)
    page.goto(f"/garage/jobs/{job_id}")
    page.wait_for_selector("#evaluate-track option[value='slipstream_speedway']", state="attached")
    assert page.input_value("#evaluate-track") == "slipstream_speedway"
    page.wait_for_selector("#submit-event option", state="attached")
    assert "not loaded" not in page.inner_text("#submit-event")
    assert len(failed) == 2
    assert page.query_selector("#evaluate-result.error, #submit-result.error") is None

    page.unroute("**/api/garage/catalogue")
    page.route("**/api/garage/catalogue", lambda route: route.abort())
    page.goto(f"/garage/jobs/{job_id}")
    page.wait_for_selector("#evaluate-result.error", timeout=20_000)
    assert "track list did not load" in page.inner_text("#evaluate-result")
    assert "did not answer" in page.inner_text("#evaluate-result")
    assert page.eval_on_selector_all("#evaluate-track option", "os => os.length") == 0
