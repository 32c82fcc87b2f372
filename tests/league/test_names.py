"""Names people choose (aliases, model and event names) follow one rule: no control or
invisible characters, spaces around them trimmed, not blank. The CLI prints them literally,
never as Rich markup. Real server, SQLite and PostgreSQL."""

from __future__ import annotations

from typing import Any

import pytest
from rich.console import Console
from typer.testing import CliRunner

from league import cli, crud
from league.schemas import clean_name
from tests.league.conftest import League, make_model_zip
from tests.league.helpers import car, create_event, enter, record, upload

runner = CliRunner()
BAD_NAMES = ["abc\n", "   ", "\x00x", "a\tb", "right\u202eleft"]


@pytest.mark.parametrize("name", BAD_NAMES)
def test_the_rule_refuses_control_characters_and_blanks(name: str) -> None:
    with pytest.raises(ValueError, match=r"control|blank"):
        clean_name(name)


def test_the_rule_trims_spaces_and_keeps_brackets() -> None:
    assert clean_name("  oops [/bold] x ") == "oops [/bold] x"


def _refused(response: Any, field: str) -> None:
    assert response.status_code == 422, response.text
    detail = response.json()["detail"]
    assert f"{field}:" in detail and ("control" in detail or "blank" in detail), detail


@pytest.mark.parametrize("name", BAD_NAMES)
def test_the_api_refuses_bad_names_naming_the_field(league: League, name: str) -> None:
    path = make_model_zip(league.models_dir, 501)
    with league.client("admin") as admin:
        _refused(admin.post("/api/events", json={"name": name}), "name")
        _refused(admin.post("/api/racers", json={"alias": name}), "alias")
    with league.client("alice") as alice:
        files = {"file": (path.name, path.read_bytes())}
        _refused(alice.post("/api/models", files=files, data={"name": name}), "name")


def test_the_api_trims_names(league: League) -> None:
    with league.client("admin") as admin:
        event = admin.post("/api/events", json={"name": "  Spaced Cup  "})
        racer = admin.post("/api/racers", json={"alias": " spaced "})
    assert event.status_code == 201 and event.json()["name"] == "Spaced Cup"
    assert racer.status_code == 201 and racer.json()["alias"] == "spaced"
    assert upload(league, "alice", seed=502, name="  my model ")["name"] == "my model"


def test_the_cli_refuses_and_trims_names(tmp_path) -> None:
    data = str(tmp_path / "data")
    bad = runner.invoke(cli.app, ["create-event", "--name", "abc\n", "--data-dir", data])
    assert bad.exit_code == 1 and "name" in bad.output and "control" in bad.output
    blank = runner.invoke(cli.app, ["create-racer", "   ", "--data-dir", data])
    assert blank.exit_code == 2 and "blank" in blank.output
    made = runner.invoke(cli.app, ["create-event", "--name", " [b]Cup[/b] ", "--data-dir", data])
    assert made.exit_code == 0, made.output
    assert ": [b]Cup[/b] (time_trial" in made.output


def test_standings_print_names_literally(
    league: League, monkeypatch: pytest.MonkeyPatch
) -> None:
    event = create_event(league, name="oops [/bold] x", seeds=[0])
    # Rows stored before the rule (or written around the API) may hold anything.
    with league.sessions() as session:
        _racer, token = crud.create_racer(session, "x[red]y")
    league.tokens["x[red]y"] = token
    model = upload(league, "x[red]y", seed=503)
    entry = enter(league, "x[red]y", event["id"], model["id"])
    record(league, event["id"], {entry["entry_id"]: car("a")})
    monkeypatch.setattr(cli, "console", Console(width=250))
    shown = runner.invoke(cli.app, ["standings", str(event["id"]), "--server", league.url])
    assert shown.exit_code == 0, shown.output
    assert "oops [/bold] x (time_trial, total time)" in shown.output
    assert "x[red]y" in shown.output
