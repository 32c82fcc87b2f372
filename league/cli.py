"""The ``slipstream`` command: one entry point, a subcommand group per package."""

from __future__ import annotations

import typer

from arena.cli import race_command
from league.league_cli import app as league_app
from submissions.cli import app as model_app
from tracks.cli import app as tracks_app

app = typer.Typer(
    name="slipstream",
    help="Slipstream: a self-hosted racing league for reinforcement-learning cars.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)
app.add_typer(tracks_app, name="tracks", help="Tracks: list, show, import, racing line.")
app.add_typer(model_app, name="model", help="Model files: validate, inspect, pre-flight.")
app.add_typer(league_app, name="league", help="The league: server, racers, events, standings.")
app.command("race", help="Race built-in drivers on a track.")(race_command)


@app.command()
def demo(
    out: str = typer.Option("slipstream-demo", help="Folder for the demo's pictures."),
) -> None:
    """Show the built-in tracks with their physical-limit lap times and draw one."""
    from league.demo import run_demo

    run_demo(out)
