"""The analysis bench in real Chromium: an edited reward re-scored over a stored race's
trace in the sandbox and drawn as a heat line with per-lap totals; a broken reward marked
at its line; two runs' curves overlaid."""

from __future__ import annotations

import os

import pytest

from league.models import TrainingEvent, TrainingJob
from league.training.sandbox import probe
from tests.league.conftest import League
from tests.web.data import Site
from tests.web.test_browser import sign_in
from tests.web.test_csp import violations, watch_csp
from tests.web.test_training_page import _iteration

EDITOR = "document.querySelector('.CodeMirror').CodeMirror"
sandboxed = pytest.mark.skipif(
    probe() is not None and os.environ.get("CI") != "true",
    reason=f"this host cannot sandbox reward functions: {probe()} (CI installs bubblewrap)",
)


@sandboxed
def test_a_stored_race_is_rescored_as_a_heat_line_with_lap_totals(
    page, league: League, site: Site
) -> None:
    console = watch_csp(page)
    sign_in(page, league, "alice")
    page.goto(f"/garage/bench?race={site.races['alice']}&car=alice")
    page.wait_for_selector(".CodeMirror")
    page.evaluate(
        f"{EDITOR}.setValue('def reward_function(params):\\n    return params[\"speed\"]\\n')"
    )
    page.click("#rescore")
    page.wait_for_selector("#rescore-result.ok")
    steps = int(page.get_attribute("#heat-new", "data-steps"))
    assert steps > 10
    laps = page.eval_on_selector_all(
        "#rescore-laps tbody tr", "rs => rs.map(r => r.cells[1].innerText)"
    )
    assert laps and all(float(total) > 0 for total in laps)  # a moving car earns its speed
    assert f"{steps} steps" in page.inner_text("#rescore-result")
    assert violations(page, console) == []


@sandboxed
def test_a_broken_reward_is_marked_at_its_line(page, league: League, site: Site) -> None:
    sign_in(page, league, "alice")
    page.goto(f"/garage/bench?race={site.races['alice']}&car=alice")
    page.wait_for_selector(".CodeMirror")
    broken = "def reward_function(params):\\n    x = 1\\n    return x / 0\\n"
    page.evaluate(f"{EDITOR}.setValue('{broken}')")
    page.click("#rescore")
    page.wait_for_selector("#rescore-result.error")
    assert "line 3" in page.inner_text("#rescore-result")
    assert page.get_attribute(".CodeMirror", "data-marked-lines") == "3"


def _run(league: League, name: str, rewards: list[float]) -> int:
    with league.sessions() as session:
        job = TrainingJob(
            owner_id=league.ids["alice"], name=name, status="done",
            spec={"options": {}}, reward_source="", minutes=1,
        )  # fmt: skip
        session.add(job)
        session.flush()
        for i, reward in enumerate(rewards):
            record = _iteration(i, reward, 9.0 if i % 2 else None)
            session.add(TrainingEvent(job_id=job.id, kind="iteration", data=record))
        session.commit()
        return job.id


def test_two_runs_overlay_their_curves(page, league: League) -> None:
    first = _run(league, "compare-a", [1.0, 2.0, 3.0, 4.0])
    second = _run(league, "compare-b", [2.0, 2.5, 2.0])
    sign_in(page, league, "alice")
    page.goto(f"/garage/bench?compare={first}&compare={second}")
    page.wait_for_selector("#compare-reward[data-lines='2']")
    assert page.get_attribute("#compare-lap", "data-lines") == "2"
    checked = page.eval_on_selector_all("#compare-jobs input:checked", "bs => bs.map(b => b.value)")
    assert sorted(map(int, checked)) == sorted([first, second])
