"""``slipstream league`` commands: create-racer, create-event, submit, standings."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from league.cli import app
from tests.league.conftest import League, make_model_zip

runner = CliRunner()


def test_create_racer_and_event_in_a_data_dir(tmp_path) -> None:
    data = str(tmp_path / "data")
    made = runner.invoke(app, ["create-racer", "dora", "--admin", "--data-dir", data])
    assert made.exit_code == 0, made.output
    assert "admin" in made.output and len(made.output.strip().splitlines()[-1]) >= 40
    again = runner.invoke(app, ["create-racer", "dora", "--data-dir", data])
    assert again.exit_code == 1 and "taken" in again.output
    ruleset = tmp_path / "cup.json"
    ruleset.write_text(json.dumps({"name": "File Cup", "laps": 2, "seeds": [3, 4]}))
    event = runner.invoke(app, ["create-event", "-f", str(ruleset), "--data-dir", data])
    assert event.exit_code == 0 and "File Cup" in event.output
    bad = runner.invoke(app, ["create-event", "--name", "x", "--laps", "0", "--data-dir", data])
    assert bad.exit_code == 1 and "laps" in bad.output


def test_submit_and_standings_against_the_server(league: League) -> None:
    with league.client("admin") as admin:
        event = admin.post("/api/events", json={"name": "CLI Cup"}).json()
    path = make_model_zip(league.models_dir, 401)
    token = league.tokens["alice"]
    args = ["submit", str(path), "--event", str(event["id"]), "--server", league.url]
    done = runner.invoke(app, [*args, "--token", token])
    assert done.exit_code == 0, done.output
    assert "jobs queued" in done.output
    broken = league.models_dir / "broken.zip"
    broken.write_bytes(b"not a zip")
    refused = runner.invoke(app, ["submit", str(broken), "--event", "1", "--token", token])
    assert refused.exit_code == 1 and "nothing was uploaded" in refused.output
    table = runner.invoke(app, ["standings", str(event["id"]), "--server", league.url])
    assert table.exit_code == 0 and "CLI Cup" in table.output
