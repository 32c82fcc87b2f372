"""The garage pages in real headless Chromium: the racer's jobs and models with their
actions, and the create-a-model form (reward samples, Validate marking the failing line,
the action-space builder agreeing with the server), all under the CSP."""

from __future__ import annotations

import os

import pytest

from agents.action_spaces import console_action_space
from league.models import TrainingJob, utcnow
from league.training.sandbox import probe
from tests.league.conftest import League
from tests.web.data import Site
from tests.web.test_browser import sign_in
from tests.web.test_csp import violations, watch_csp

BROKEN_REWARD = "def reward_function(params):\n    x = 1\n    return missing_name\n"
FIXED_REWARD = "def reward_function(params):\n    x = 1\n    return float(x)\n"
OPTIONS = {
    "track": "slipstream_speedway",
    "direction": "cw",
    "race_type": "time_trial",
    "sensors": "camera",
    "action_space": "console:20:3:1.2:2",
    "also_tracks": "grand_tour",
    "eval_also_tracks": True,
}
EDITOR = "document.querySelector('.CodeMirror').CodeMirror"


def _add_job(league: League, who: str, name: str, status: str, **fields: object) -> int:
    """A training job row as a trainer leaves it (no trainer runs in these tests)."""
    spec = {"options": OPTIONS, "recipe": None, "hyperparameters": {"lr": 0.001}, "minutes": 5}
    with league.sessions() as session:
        job = TrainingJob(
            owner_id=league.ids[who],
            name=name,
            status=status,
            spec=spec,
            reward_source=FIXED_REWARD,
            minutes=5,
            **fields,
        )
        session.add(job)
        session.commit()
        return job.id


def _job(league: League, job_id: int) -> TrainingJob | None:
    with league.sessions() as session:
        job = session.get(TrainingJob, job_id)
        if job is not None:
            session.expunge(job)
        return job


def _rows(page, table: str) -> list[list[str]]:
    return page.eval_on_selector_all(
        f"#{table} tbody tr", "rows => rows.map(r => Array.from(r.cells, c => c.innerText.trim()))"
    )


def test_the_garage_lists_the_racers_jobs_and_models_and_acts_on_them(
    page, league: League, site: Site
) -> None:
    console = watch_csp(page)
    page.goto("/garage")
    page.wait_for_selector("main[data-loaded=true]")
    assert "not signed in" in page.inner_text("#garage-note")

    done = _add_job(
        league, "alice", "garage-done", "done", best_lap_ms=12_345,
        model_id=site.models["alice"], run_sha256="0" * 64, finished_at=utcnow(),
    )  # fmt: skip
    running = _add_job(league, "alice", "garage-running", "running", started_at=utcnow())
    _add_job(league, "bob", "garage-bob", "queued")
    sign_in(page, league, "alice")
    page.goto("/garage")
    page.wait_for_selector(f"#jobs tr[data-job-id='{done}']")
    names = [row[1] for row in _rows(page, "jobs")]
    assert "garage-done" in names and "garage-running" in names and "garage-bob" not in names
    row = page.locator(f"#jobs tr[data-job-id='{done}']")
    assert "0:12.345" in row.inner_text() and "done" in row.inner_text()
    assert row.locator("img").get_attribute("src")  # the track's thumbnail
    assert row.locator("a", has_text="garage-done").get_attribute("href") == f"/garage/jobs/{done}"
    assert row.locator("a.model-link").get_attribute("href") == f"/models/{site.models['alice']}"
    with league.client("alice") as alice:
        models = alice.get("/api/models").json()
    assert [r[0] for r in _rows(page, "models")] == [m["name"] for m in models]

    page.locator(f"#jobs tr[data-job-id='{running}'] button", has_text="stop").click()
    page.wait_for_selector(f"#jobs tr[data-job-id='{running}'] button[disabled]:has-text('stop')")
    assert _job(league, running).stop_requested_at is not None

    page.once("dialog", lambda dialog: dialog.accept())
    row.locator("button", has_text="delete").click()
    page.wait_for_selector(f"#jobs tr[data-job-id='{done}']", state="detached")
    assert _job(league, done) is None

    clone = _add_job(league, "alice", "garage-parent", "done", run_sha256="1" * 64)
    page.goto(f"/garage/new?clone={clone}")
    page.wait_for_selector("#create-form[data-ready=true]")
    body = page.evaluate("() => Create.jobBody(formState())")
    assert body["clone_of"] == clone and body["name"] == "garage-parent-clone"
    assert body["options"] == OPTIONS and body["hyperparameters"] == {"lr": 0.001}
    assert not page.is_checked("#anchor")  # its parent learned from its reward alone
    assert page.is_disabled("#anchor-weight")

    # A clone of a fast-start (imitation) job learns from its reward by PPO, held near
    # the scripted driver; fast start and the anchor exclude each other.
    imitation = _add_job(league, "alice", "garage-imitation", "done", run_sha256="2" * 64)
    with league.sessions() as session:
        job = session.get(TrainingJob, imitation)
        job.spec = {**job.spec, "recipe": "time_trial"}
        session.commit()
    page.goto(f"/garage/new?clone={imitation}")
    page.wait_for_selector("#create-form[data-ready=true]")
    assert page.is_checked("#anchor") and not page.is_checked("#fast-start")
    body = page.evaluate("() => Create.jobBody(formState())")
    assert body["options"] == {**OPTIONS, "anchor": "pursuit"} and "recipe" not in body
    page.fill("#anchor-weight", "0.5")  # how strongly: sent only when not the default 1
    body = page.evaluate("() => Create.jobBody(formState())")
    assert body["options"] == {**OPTIONS, "anchor": "pursuit", "anchor_weight": 0.5}
    page.check("#fast-start")
    assert page.is_disabled("#anchor") and not page.is_checked("#anchor")
    assert page.is_disabled("#anchor-weight")
    page.goto("/garage/new")
    page.wait_for_selector("#create-form[data-ready=true]")
    assert page.is_disabled("#anchor")  # nothing to stay near: not a clone
    # Further tracks for the training races: any but the chosen one, sent comma-separated.
    page.click("label[for=track-slipstream_speedway]")
    assert page.is_disabled("#also-track-slipstream_speedway")
    page.check("#also-track-grand_tour")
    page.check("#also-track-hairpin_hollow")
    options = page.evaluate("() => Create.jobBody(formState())")["options"]
    assert options["track"] == "slipstream_speedway"
    assert options["also_tracks"] == "hairpin_hollow,grand_tour"  # the catalogue's order
    assert "eval_also_tracks" not in options
    page.check("#eval-also-tracks")
    options = page.evaluate("() => Create.jobBody(formState())")["options"]
    assert options["eval_also_tracks"] is True
    page.click("label[for=track-grand_tour]")
    assert page.is_disabled("#also-track-grand_tour")
    assert not page.is_checked("#also-track-grand_tour")
    page.wait_for_load_state("networkidle")
    assert violations(page, console) == []


@pytest.mark.skipif(
    probe() is not None and os.environ.get("CI") != "true",
    reason=f"this host cannot sandbox reward checks: {probe()} (CI installs bubblewrap)",
)
def test_create_a_model_validates_the_reward_and_builds_the_action_space(
    page, league: League
) -> None:
    console = watch_csp(page)
    sign_in(page, league, "alice")
    page.goto("/garage/new")
    page.wait_for_selector("#create-form[data-ready=true]")
    with league.client() as anyone:
        samples = anyone.get("/api/garage/catalogue").json()["reward_samples"]
    sample = samples[-1]
    page.select_option("#reward-sample", sample["name"])
    page.click("#reward-load")
    assert page.evaluate(f"() => {EDITOR}.getValue()") == sample["source"]

    page.fill("#model-name", "garage-new")
    page.evaluate(f"text => {EDITOR}.setValue(text)", BROKEN_REWARD)
    page.click("#validate")
    page.wait_for_selector("#validate-result.error")
    assert "line 3" in page.inner_text("#validate-result")
    assert page.get_attribute(".CodeMirror", "data-marked-lines") == "3"

    # The console builder: 30 degrees in 5 steps, 1.5 m/s in 2 -> 10 actions, as the server
    # builds them; editing one action turns the spec into a list the server accepts.
    page.fill("#max-steer", "30")
    page.select_option("[aria-label='Steering angle granularity']", "5")
    page.fill("#max-speed", "1.5")
    page.select_option("[aria-label='Speed granularity']", "2")
    assert page.inner_text("#action-spec") == "console:30:5:1.5:2"
    table = [tuple(map(float, r[1:3])) for r in _action_rows(page)]
    expected = console_action_space(30, 5, 1.5, 2).actions
    assert table == [(a.steering_angle, a.speed) for a in expected]
    assert page.locator(".polar .polar-action").count() == 10
    page.fill("[aria-label='Action 0 speed']", "0.5")
    spec = page.inner_text("#action-spec")
    assert spec.startswith("list:-30/0.5,-30/1.5,-15/0.75") and spec.count("/") == 10
    # Dragged on the graph to straight ahead, three quarters of the way to the outer ring
    # (the top speed, 1.5 m/s), action 0 drives straight at about 1.125 m/s; the table
    # follows.
    _drag_ahead(page, ".polar .polar-action[data-index='0']", 0.75)
    steer = float(page.input_value("[aria-label='Action 0 steering angle']"))
    speed = float(page.input_value("[aria-label='Action 0 speed']"))
    assert abs(steer) <= 3 and abs(speed - 1.125) <= 0.1, (steer, speed)
    assert page.inner_text("#action-spec").startswith(f"list:{steer:g}/{speed:g},-30/1.5")

    page.evaluate(f"text => {EDITOR}.setValue(text)", FIXED_REWARD)
    page.click("#validate")
    page.wait_for_selector("#validate-result.ok")
    assert page.get_attribute(".CodeMirror", "data-marked-lines") is None

    # A race type's own settings: head-to-bot offers its bots, their speed and lane
    # changes at the league's defaults; only what the racer changes goes to the server.
    page.check("#race-head_to_bot")
    assert page.input_value("#race-bots") == "3" and page.locator("#race-bot_speed").count()
    page.fill("#race-bots", "2")
    page.fill("#model-description", "two bots at the default speed")
    body = page.evaluate("() => Create.jobBody(formState())")
    assert body["options"]["race_type"] == "head_to_bot" and body["options"]["bots"] == 2
    assert "bot_speed" not in body["options"]
    assert body["description"] == "two bots at the default speed"
    page.click("#validate")
    page.wait_for_selector("#validate-result.ok")
    page.fill("#race-bots", "9")
    page.click("#validate")
    page.wait_for_selector("#validate-result.error")
    assert "bots" in page.inner_text("#validate-result")
    page.check("#race-object_avoidance")
    assert page.locator("#race-bots").count() == 0 and page.input_value("#race-boxes") == "6"

    page.check("#action-type-continuous")
    assert page.inner_text("#action-spec").startswith("continuous:")
    assert page.locator(".polar .polar-sector").count() == 1
    # The sector's right-hand edge (the lowest steering angle) dragged to straight ahead.
    _drag_ahead(page, ".polar .polar-handle[data-bound='steerLow']", 0.75)
    low = float(page.input_value("#cont-steerLow"))
    assert abs(low) <= 3, low
    assert page.inner_text("#action-spec").startswith(f"continuous:{low:g}:30:")
    assert violations(page, console) == []


def _ahead(page, fraction: float) -> tuple[float, float]:
    """The page point straight ahead of the car, ``fraction`` of the way out along the
    graph's straight-ahead ray (1: its outer ring, the graph's top speed)."""
    return page.evaluate(
        """(fraction) => {
          const svg = document.querySelector('.polar');
          const rays = Array.from(svg.querySelectorAll('.polar-ray'));
          const ray = rays.find((l) => l.getAttribute('x1') === l.getAttribute('x2'));
          const [x1, y1, x2, y2] = ['x1', 'y1', 'x2', 'y2'].map((k) => +ray.getAttribute(k));
          const at = new DOMPoint(x1 + fraction * (x2 - x1), y1 + fraction * (y2 - y1));
          const shown = at.matrixTransform(svg.getScreenCTM());
          return [shown.x, shown.y];
        }""",
        fraction,
    )


def _drag_ahead(page, selector: str, fraction: float) -> None:
    """Drag the element at ``selector`` with the mouse to straight ahead of the car (see
    :func:`_ahead`), the graph scrolled into view first: the mouse acts in the viewport."""
    page.locator(".polar").scroll_into_view_if_needed()
    to = _ahead(page, fraction)
    box = page.locator(selector).bounding_box()
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.mouse.down()
    page.mouse.move(*to, steps=8)
    page.mouse.up()


def _action_rows(page) -> list[list[str]]:
    return page.eval_on_selector_all(
        "#action-table tbody tr",
        "rows => rows.map(r => Array.from(r.cells, c => c.querySelector('input')"
        " ? c.querySelector('input').value : c.textContent))",
    )
