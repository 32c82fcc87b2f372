"""``slipstream league`` commands: create-racer, create-event, submit, standings."""

from __future__ import annotations

import json

from rich.console import Console
from typer.testing import CliRunner

from league.cli import app, standings_table
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


def test_standings_table_shows_racing_metrics_of_head_to_model_events() -> None:
    row = {
        "rank": 1, "alias": "alice", "lap_count": 2, "best_lap_ms": 9100,
        "average_lap_ms": 9200, "total_time_ms": 18400, "off_track_count": 0,
        "collision_count": 3, "at_fault_collisions": 2, "reset_count": 0,
        "ranking_score_ms": 18400, "submission_count": 1, "overtakes": 4, "laps_led": 1,
        "mu": 27.5, "sigma": 7.9, "ordinal": 3.8,
    }  # fmt: skip
    board = {"race_type": "head_to_model", "ranking_metric": "total", "rows": [row]}
    console = Console(width=250, record=True)
    console.print(standings_table({"name": "Duel", "race_type": "head_to_model"}, board))
    header, cells = _table_lines(console.export_text())
    shown = dict(zip(header, cells, strict=True))
    assert shown["at fault"] == "2" and shown["collisions"] == "3"
    assert shown["overtakes"] == "4" and shown["laps led"] == "1"
    time_trial = {**board, "race_type": "time_trial"}
    console = Console(width=250, record=True)
    console.print(standings_table({"name": "TT", "race_type": "time_trial"}, time_trial))
    header, _ = _table_lines(console.export_text())
    assert "at fault" in header and "overtakes" not in header


def _table_lines(text: str) -> tuple[list[str], list[str]]:
    """The header cells and the first row's cells of a Rich table printed as text."""
    rows = [line for line in text.splitlines() if line.startswith(("┃", "│"))]
    split = [[c.strip() for c in line.strip("┃│").replace("┃", "│").split("│")] for line in rows]
    return split[0], split[1]
