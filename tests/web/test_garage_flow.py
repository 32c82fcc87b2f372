"""The garage end to end, as a new racer uses it, in real Chromium against a real server,
trainer and worker: open the garage, create a model from a sample reward, break the
reward and see Validate point at the line, fix it, train for one minute while the reward
graph and the live view move, choose the run's last checkpoint as the model, evaluate it
on another track, submit it to an open event in one click and find it on the event's
leaderboard, then re-score its evaluation race with an edited reward and see the heat line.

With ``SLIPSTREAM_WEB_SCREENSHOTS=docs/img`` the pages are saved for ``docs/web.md``.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import select

from league import crud
from league.models import Entry
from league.training.sandbox import probe
from tests.league.conftest import League
from tests.league.helpers import create_event, start_daemon
from tests.web.test_browser import TOKEN_KEY
from tests.web.test_csp import violations, watch_csp

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        probe() is not None and os.environ.get("CI") != "true",
        reason=f"this host cannot sandbox training jobs: {probe()} (CI installs bubblewrap)",
    ),
]
TRACK = "slipstream_speedway"
EVALUATION_TRACK = "hairpin_hollow"
EDITOR = "document.querySelector('.CodeMirror').CodeMirror"
BROKEN = "def reward_function(params):\n    speed = params['speed']\n    return speed * missing\n"
FASTER = "def reward_function(params):\n    return params['speed'] / 4.0\n"


@pytest.fixture
def daemons(league: League, tmp_path: Path) -> Iterator[list[subprocess.Popen]]:
    """A trainer (one env worker) and an evaluation worker, stopped after the test."""
    started = [
        start_daemon(
            league,
            "league.training.trainer",
            ["garage-trainer"],
            tmp_path / "trainer.log",
            SLIPSTREAM_TRAINING_WORKERS="1",
        ),
        start_daemon(
            league, "league.jobs.worker", ["--name", "garage-worker"], tmp_path / "worker.log"
        ),
    ]
    yield started
    for process in started:
        process.send_signal(signal.SIGTERM)
    for process in started:
        process.wait(60)


def _new_racer(league: League, alias: str) -> str:
    with league.sessions() as session:
        _, token = crud.create_racer(session, alias)
    return token


def _shot(page, folder: Path | None, name: str, selector: str) -> None:
    """Save ``selector``'s element for the docs (scrolled into view) when asked to."""
    if folder is not None:
        page.locator(selector).screenshot(path=str(folder / name))


def test_a_new_racer_creates_trains_evaluates_submits_and_rescores_in_the_browser(
    page, league: League, daemons, screenshot_dir: Path | None
) -> None:
    console = watch_csp(page)
    token = _new_racer(league, "dana")
    page.add_init_script(f"window.localStorage.setItem({TOKEN_KEY!r}, {token!r});")
    event = create_event(league, name="Garage Cup", track=TRACK, seeds=[0])

    page.goto("/garage")
    page.wait_for_selector("main[data-loaded=true]")
    page.click("#create-model")
    page.wait_for_url("**/garage/new")
    page.wait_for_selector(f"#track-{TRACK}")
    page.fill("#model-name", "dana-speedway")
    page.check(f"#track-{TRACK}")
    page.select_option("#reward-sample", "follow_center_line")
    page.click("#reward-load")
    sample = page.evaluate(f"{EDITOR}.getValue()")
    assert "def reward_function(params)" in sample

    page.evaluate(f"{EDITOR}.setValue({BROKEN!r})")
    page.click("#validate")
    page.wait_for_selector("#validate-result.error")
    assert "line 3" in page.inner_text("#validate-result")
    assert page.get_attribute(".CodeMirror", "data-marked-lines") == "3"
    _shot(page, screenshot_dir, "garage-validate.png", "#create-form")

    page.evaluate(f"{EDITOR}.setValue({sample!r})")
    page.click("#validate")
    page.wait_for_selector("#validate-result.ok")
    page.fill("#minutes", "1")
    page.check("#fast-start")
    page.click("#train")
    page.wait_for_url(re.compile(r".*/garage/jobs/\d+$"))
    job_id = int(page.url.rsplit("/", 1)[1])

    # The reward graph and the live view move while the job trains.
    page.wait_for_selector("#status[data-status=running]", timeout=60_000)
    page.wait_for_function(
        "() => Number(document.getElementById('reward-graph').dataset.points) >= 2",
        timeout=90_000,
    )
    page.wait_for_function(
        "() => Number(document.getElementById('live-view').dataset.poses) > 0", timeout=30_000
    )
    _shot(page, screenshot_dir, "garage-training.png", "#training")
    page.wait_for_selector("#status[data-status=done]", timeout=180_000)
    with league.client("admin") as admin:
        job = admin.get(f"/api/training-jobs/{job_id}").json()
    assert job["model_id"] is not None, job

    # The run kept its checkpoints; the job's model is the best one's. Choose the last.
    page.wait_for_selector("#checkpoints tr[data-checkpoint=last]")
    assert page.is_checked("#checkpoint-best")
    page.check("#checkpoint-last")
    page.click("#use-checkpoint")
    page.wait_for_selector("#checkpoint-result.ok")
    chosen = int(re.search(r"Model (\d+)", page.inner_text("#checkpoint-result")).group(1))
    assert page.get_attribute("#model-link a", "href") == f"/models/{chosen}"

    # Evaluate on another track; the worker races it; its replay is linked.
    page.select_option("#evaluate-track", EVALUATION_TRACK)
    page.select_option("#evaluate-direction", "cw")
    page.fill("#evaluate-laps", "1")
    page.click("#evaluate")
    page.wait_for_selector("#evaluations a[href^='/races/']", timeout=120_000)
    race_href = page.get_attribute("#evaluations a[href^='/races/']", "href")

    # Submit to the open event in one click; the model appears on its leaderboard.
    page.wait_for_selector(f"#submit-event option[value='{event['id']}']", state="attached")
    page.select_option("#submit-event", str(event["id"]))
    page.click("#submit")
    page.wait_for_selector(f"#submit-result a[href='/events/{event['id']}']")
    _shot(page, screenshot_dir, "garage-evaluate-submit.png", "#model-actions")
    with league.sessions() as session:
        entered = session.scalars(select(Entry.model_id).where(Entry.event_id == event["id"]))
        assert list(entered) == [chosen]
    page.click(f"#submit-result a[href='/events/{event['id']}']")
    page.wait_for_function(
        "() => Array.from(document.querySelectorAll('#leaderboard tbody tr'))"
        ".some(r => r.cells[1] && r.cells[1].textContent === 'dana')",
        timeout=120_000,
    )

    # Re-score the evaluation race with an edited reward: a heat line along its path.
    race_id = int(race_href.rsplit("/", 1)[1])
    with league.client() as anyone:
        car = anyone.get(f"/api/races/{race_id}").json()["cars"][0]["car_name"]
    page.goto(f"/garage/bench?race={race_id}&car={car}")
    page.wait_for_selector(".CodeMirror")
    page.evaluate(f"{EDITOR}.setValue({FASTER!r})")
    page.click("#rescore")
    page.wait_for_function(
        "() => Number(document.getElementById('heat-new').dataset.steps) > 0", timeout=60_000
    )
    assert page.eval_on_selector_all("#rescore-laps tbody tr", "rows => rows.length") >= 1
    _shot(page, screenshot_dir, "garage-rescore.png", "#rescore-section")
    assert violations(page, console) == []
