"""The ``slipstream`` command: a subcommand group per package, mounted in one Typer app.

``tracks`` (tracks), ``race`` (arena), ``train`` and ``evaluate`` (agents), ``model``
(submissions, with ``pack`` from agents), ``league`` (league), and ``demo``, which runs the
whole league locally.
"""

from __future__ import annotations

import typer

from agents.cli import evaluate_command, train
from agents.pack_command import pack_command
from league.cli import app as league_app
from slipstream.race import race_command
from submissions.cli import app as model_app
from tracks.cli import app as tracks_app

app = typer.Typer(
    name="slipstream",
    help="Slipstream: a self-hosted racing league for reinforcement-learning cars.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)
app.add_typer(tracks_app, name="tracks", help="Tracks: list, show, import, racing line.")
model_app.command("pack")(pack_command)  # agents' command: it reads runs and DeepRacer files
app.add_typer(model_app, name="model", help="Model files: pack, validate, inspect, pre-flight.")
app.add_typer(league_app, name="league", help="The league: server, racers, events, standings.")
app.command("race", help="Race built-in drivers, or model files head to head.")(race_command)
app.command("train", help="Train a policy with PPO (rsl-rl), DeepRacer-style.")(train)
app.command("evaluate", help="Race a training run's policy and print its results.")(
    evaluate_command
)


@app.command()
def demo(
    out: str = typer.Option("slipstream-demo", help="Folder for the demo's data, logs, pictures."),
    port: int = typer.Option(8000, help="Port of the demo's league server."),
    serve: bool = typer.Option(True, help="Keep serving after the first leaderboards."),
    round_interval: int = typer.Option(60, help="Seconds between head-to-model rounds."),
    timeout: float = typer.Option(300.0, help="Longest wait for the first results, seconds."),
) -> None:
    """The whole league on this machine: tracks, server, scheduler, worker, leaderboards."""
    from league.demo import run_demo

    run_demo(out, port=port, keep_serving=serve, round_interval_s=round_interval, timeout_s=timeout)
