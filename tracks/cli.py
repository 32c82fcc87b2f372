"""``slipstream tracks``: list, show, import tracks and compute their racing lines."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from tracks.catalog import Direction, builtin_names, get_track, import_track, list_tracks
from tracks.track import Track, TrackError

app = typer.Typer(help="Tracks: list, inspect, import, racing lines.", no_args_is_help=True)

DirectionOption = Annotated[
    Direction | None, typer.Option("--direction", "-d", help="Drive it ccw or cw.")
]
JsonOption = Annotated[bool, typer.Option("--json", help="Print JSON instead of text.")]


def _fail(message: str) -> typer.Exit:
    err = Console(stderr=True, soft_wrap=True)
    err.print(f"[bold red]error:[/] {escape(message)}", highlight=False)
    return typer.Exit(1)


def _load(name: str, direction: Direction | None) -> Track:
    try:
        return get_track(name, direction)
    except TrackError as exc:
        raise _fail(str(exc)) from None


def _summary(track: Track) -> dict[str, Any]:
    return {
        "name": track.name,
        "display_name": track.display_name,
        "description": track.description,
        "source": "builtin" if track.name in builtin_names() else "user",
        "loop": track.is_loop,
        "direction": track.direction,
        "length": round(track.length, 3),
        "width": round(track.width, 3),
        "min_width": round(float(track.widths.min()), 3),
        "max_width": round(float(track.widths.max()), 3),
        "waypoints": len(track.waypoints),
        "bounds": [round(v, 3) for v in track.bounds],
    }


def _print_json(doc: Any) -> None:
    typer.echo(json.dumps(doc, indent=2))


@app.command("list")
def list_command(as_json: JsonOption = False) -> None:
    """List built-in and imported tracks."""
    infos = list_tracks()
    if as_json:
        _print_json([asdict(i) for i in infos])
        return
    table = Table(title="Tracks")
    for column in ("name", "display name", "length (m)", "width (m)", "direction", "source"):
        table.add_column(
            column, justify="right" if "(m)" in column else "left", no_wrap=column == "name"
        )
    for i in infos:
        table.add_row(
            i.name,
            i.display_name,
            f"{i.length:.2f}",
            f"{i.width:.2f}",
            i.direction if i.is_loop else "open",
            i.source,
        )
    Console().print(table)


@app.command("show")
def show_command(
    name: str,
    direction: DirectionOption = None,
    png: Annotated[Path | None, typer.Option("--png", help="Save a picture here.")] = None,
    raceline: Annotated[bool, typer.Option("--raceline", help="Add the racing line.")] = False,
    as_json: JsonOption = False,
) -> None:
    """Describe one track; optionally draw it and its racing line."""
    track = _load(name, direction)
    doc = _summary(track)
    line = None
    if raceline:
        from tracks.raceline import compute_racing_line

        line = compute_racing_line(track)
        doc["lap_time"] = round(line.lap_time, 3)
    if png is not None:
        from tracks.plot import plot_track

        try:
            plot_track(track, png, racing_line=line)
        except OSError as exc:
            raise _fail(f"cannot write {png}: {exc}") from None
        doc["png"] = str(png)
    if as_json:
        _print_json(doc)
        return
    console = Console()
    title = f"{escape(track.display_name)}[/] ({escape(track.name)}) {escape(track.description)}"
    console.print(f"[bold]{title}")
    for key in ("source", "loop", "direction", "length", "width", "min_width", "max_width"):
        console.print(f"  {key.replace('_', ' ')}: {doc[key]}")
    if line is not None:
        console.print(f"  physical-limit lap time: {line.lap_time:.3f} s")
    if png is not None:
        console.print(f"  picture: {png}")


@app.command("import")
def import_command(
    file: Path,
    name: Annotated[str | None, typer.Option("--name", help="Store under this name.")] = None,
    force: Annotated[bool, typer.Option("--force", help="Replace a user track.")] = False,
    as_json: JsonOption = False,
) -> None:
    """Import a track file (.npy, .json, .yaml) into the user track directory."""
    try:
        track = import_track(file, name, overwrite=force)
    except (TrackError, OSError) as exc:
        raise _fail(str(exc)) from None
    if as_json:
        _print_json(_summary(track))
        return
    Console().print(
        f"imported [bold]{track.name}[/]: {track.length:.2f} m long, {track.width:.2f} m wide, "
        f"{track.direction if track.is_loop else 'open'}"
    )


@app.command("raceline")
def raceline_command(
    name: str,
    direction: DirectionOption = None,
    as_json: JsonOption = False,
) -> None:
    """Compute the racing line and the physical-limit lap time of DeepRacer's car."""
    from tracks.raceline import CarLimits, centerline_profile, compute_racing_line

    track = _load(name, direction)
    limits = CarLimits()
    line = compute_racing_line(track, limits)
    centre = centerline_profile(track, limits)
    doc = {
        "track": track.name,
        "display_name": track.display_name,
        "direction": track.direction,
        "length": round(track.length, 3),
        "width": round(track.width, 3),
        "racing_line_length": round(line.length, 3),
        "lap_time": round(line.lap_time, 3),
        "centerline_lap_time": round(centre.lap_time, 3),
        "top_speed": round(float(line.speed.max()), 3),
        "min_speed": round(float(line.speed.min()), 3),
        "limits": asdict(limits),
    }
    if as_json:
        _print_json(doc)
        return
    console = Console()
    name = escape(track.display_name)
    console.print(f"[bold]{name}[/] ({escape(track.name)}, {track.direction})")
    console.print(f"  length {track.length:.2f} m, width {track.width:.2f} m")
    console.print(f"  physical-limit lap time: [bold]{line.lap_time:.3f} s[/]")
    console.print(f"  centre line at the limit: {centre.lap_time:.3f} s")
    console.print(
        f"  racing line {line.length:.2f} m, speeds {doc['min_speed']}-{doc['top_speed']} m/s"
    )
    figures = {k: v for k, v in asdict(limits).items() if k != "cornering"}
    console.print("  car limits: " + ", ".join(f"{k}={v:g}" for k, v in figures.items()))
    console.print(
        f"  cornering envelope: {len(limits.cornering)} circles, from "
        f"{limits.cornering[0][1]:g} m/s at curvature {limits.cornering[0][0]:g}/m to "
        f"{limits.cornering[-1][1]:g} m/s at {limits.cornering[-1][0]:g}/m"
        if limits.cornering
        else "  cornering: grip alone"
    )
