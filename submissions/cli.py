"""``slipstream model``: validate and inspect submission files from the command line."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console
from rich.table import Table
from rich.text import Text

from arena.actions import DiscreteActionSpace
from submissions.validator import ModelInfo, ValidationReport, validate

if TYPE_CHECKING:
    from submissions.preflight import PreflightResult

app = typer.Typer(help="Pack, check and inspect submission files.", no_args_is_help=True)
console = Console()

FileArg = Annotated[Path, typer.Argument(help="The submission archive (.zip).")]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print JSON instead of tables.")]


def print_problems(report: ValidationReport) -> None:
    """One block per problem; untrusted text is printed as plain Text, never as markup."""
    console.print(f"{len(report.problems)} problem(s):")
    for p in report.problems:
        console.print(Text.assemble("- ", (p.field, "bold"), ": ", p.message), soft_wrap=True)
        console.print(Text(f"    expected {p.expected}; found {p.found}"), soft_wrap=True)


def _describe_space(info: ModelInfo) -> str:
    space = info.action_space
    if isinstance(space, DiscreteActionSpace):
        return f"discrete, {space.n} actions, max speed {space.max_speed:g} m/s"
    s, v = space.steering_angle, space.speed
    return f"continuous, steering {s.low:g}..{s.high:g} deg, speed {v.low:g}..{v.high:g} m/s"


def print_info(info: ModelInfo) -> None:
    table = Table(show_header=False)
    table.add_column("key", no_wrap=True)
    table.add_column("value", overflow="fold")
    rows = {
        "format version": str(info.format_version),
        "archive sha256": info.archive_sha256,
        "archive size": f"{info.archive_bytes} bytes",
        "action space": _describe_space(info),
        "sensors": ", ".join(info.sensors),
        "inputs": "; ".join(f"{s.name} {s.dtype}{list(s.shape)}" for s in info.observation),
        "output": f"{info.output.convention} ({info.output.size})",
        "network": f"{info.neural_network} / preset {info.network_preset or '-'}",
        "training": f"{info.training_algorithm} {json.dumps(info.training_summary)}",
        "created at": info.created_at.isoformat(),
        "policy sha256": info.policy_sha256,
        "latency": "-" if info.latency_ms is None else f"{info.latency_ms:.3f} ms / step",
    }
    for key, value in rows.items():
        table.add_row(key, Text(value))
    console.print(table)


def _run_preflight(file: Path, track: str) -> PreflightResult:
    from arena.config import ConfigError
    from submissions.preflight import preflight

    try:
        with console.status(f"pre-flight: racing one lap on {track}..."):
            return preflight(file, track)
    except ConfigError as exc:
        console.print(Text(f"pre-flight: {exc}", style="red"))
        raise typer.Exit(1) from None


def _print_preflight(result: PreflightResult) -> None:
    best = "-" if result.best_lap is None else f"{result.best_lap:.3f} s"
    verdict = "finished" if result.finished else f"did NOT finish ({result.status})"
    console.print(
        Text(
            f"pre-flight on {result.track}: {verdict}; {result.laps_completed}/{result.laps} "
            f"laps, lap {best}, {result.off_track_count} off-track, {result.crash_count} "
            f"crashes, {result.reset_count} resets"
        )
    )


@app.command("validate")
def validate_command(
    file: FileArg,
    as_json: JsonOpt = False,
    preflight: Annotated[
        bool, typer.Option("--preflight", help="Also race the model for one lap on --track.")
    ] = False,
    track: Annotated[str | None, typer.Option("--track", help="Track for --preflight.")] = None,
) -> None:
    """Validate FILE; exit 1 and list every problem if it is refused.

    With ``--preflight --track T`` a valid model also races one lap alone on T, so you
    learn before uploading whether it can finish.
    """
    if preflight and not track:
        raise typer.BadParameter("--preflight needs --track", param_hint="--track")
    report = validate(file)
    flight = _run_preflight(file, track) if (preflight and track and report.ok) else None
    if as_json:
        doc = {"ok": report.ok, **report.model_dump(mode="json")}
        if flight is not None:
            doc["preflight"] = flight.model_dump()
        typer.echo(json.dumps(doc, indent=2))
    elif report.ok:
        console.print(Text.assemble(("valid ", "green"), str(file)))
        if report.info is not None:
            print_info(report.info)
        if flight is not None:
            _print_preflight(flight)
    else:
        console.print(Text.assemble(("refused ", "red"), str(file)))
        print_problems(report)
    if not report.ok:
        raise typer.Exit(1)


@app.command("info")
def info_command(file: FileArg, as_json: JsonOpt = False) -> None:
    """Print FILE's metadata summary (checks archive, metadata and graph; runs nothing)."""
    report = validate(file, run_policy=False)
    if as_json:
        typer.echo(json.dumps({"ok": report.ok, **report.model_dump(mode="json")}, indent=2))
    else:
        if report.info is not None:
            print_info(report.info)
        if report.problems:
            print_problems(report)
    if report.info is None:
        raise typer.Exit(1)
