"""``slipstream demo``: the whole league on one machine, in one command.

1. Shows the built-in tracks with their physical-limit lap times and draws one.
2. Creates a fresh league in ``OUT/league-data`` (SQLite): racers and four events on
   built-in tracks (time trial, object avoidance, head-to-bot, head-to-model).
3. Starts the server, the scheduler, a worker and a trainer (for training jobs, where the
   host can sandbox them) as child processes, uploads the bundled sample models through
   the API and enters them in every event.
4. Shows progress while the first evaluations run, prints each leaderboard, and keeps
   serving (URL printed) until Ctrl-C, SIGTERM or SIGHUP, any of which stops every child
   process, then the demo.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from importlib import resources
from pathlib import Path

import httpx
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from league.schemas import EventCreate
from league.settings import Settings
from league.training.launch import training_refused

SAMPLE_MODELS = (
    "sample-time-trial.zip",
    "sample-object-avoidance.zip",
    "sample-head-to-bot.zip",
    "sample-self-play.zip",
)
RACERS = ("alice", "bob", "carol", "dave")


def demo_events(round_interval_s: int) -> list[EventCreate]:
    """The four demo events: one per race type, on built-in tracks, open for a day."""
    return [
        EventCreate(name="Beginner Loop Time Trial", race_type="time_trial", laps=3,
                    time_limit_s=240.0, seeds=[0]),
        EventCreate(name="Speedway Object Avoidance", race_type="object_avoidance",
                    track="slipstream_speedway", laps=1, time_limit_s=120.0,
                    obstacles={"count": 4, "min_gap_m": 3.0}, seeds=[0]),
        EventCreate(name="Speedway Head-to-Bot", race_type="head_to_bot",
                    track="slipstream_speedway", laps=1, time_limit_s=120.0,
                    bots={"count": 2, "speed": 0.3}, seeds=[0]),
        EventCreate(name="Speedway Head-to-Model Cup", race_type="head_to_model",
                    track="slipstream_speedway", laps=1, time_limit_s=120.0,
                    round_interval_s=round_interval_s, seeds=[0]),
    ]  # fmt: skip


def print_tracks(console: Console, out: Path) -> None:
    """The built-in tracks with their yardstick lap times; a picture of the first."""
    from arena.pursuit import car_limits
    from tracks.catalog import builtin_names, get_track
    from tracks.plot import plot_track
    from tracks.raceline import centerline_profile, compute_racing_line

    limits = car_limits()
    table = Table(title="Built-in tracks (physical-limit lap: the yardstick)")
    for column in ("track", "name", "length m", "width m", "limit lap s", "centre-line lap s"):
        table.add_column(column, justify="left" if column in ("track", "name") else "right")
    lines = {}
    with console.status("computing racing lines..."):
        for name in builtin_names():
            track = get_track(name)
            lines[name] = (track, compute_racing_line(track, limits))
            table.add_row(
                track.display_name,
                name,
                f"{track.length:.2f}",
                f"{track.width:.2f}",
                f"{lines[name][1].lap_time:.2f}",
                f"{centerline_profile(track, limits).lap_time:.2f}",
            )
    console.print(table)
    console.print(
        f"car limits: top speed {limits.max_speed} m/s, grip {limits.max_lateral_accel:.2f} "
        f"m/s², accel {limits.max_accel} m/s², brake {limits.max_brake} m/s²"
    )
    first = builtin_names()[0]
    track, line = lines[first]
    console.print(f"wrote {plot_track(track, out / f'{first}.png', racing_line=line)}")


def _create_league(data_dir: Path, round_interval_s: int) -> tuple[dict[str, str], list[int]]:
    """A fresh database with racers and events; returns the racers' tokens and event ids."""
    from league import crud
    from league.db import make_engine, make_session_factory
    from league.migrations import upgrade

    if data_dir.exists():
        shutil.rmtree(data_dir)
    data_dir.mkdir(parents=True)
    engine = make_engine(f"sqlite:///{(data_dir / 'league.db').resolve()}")
    upgrade(engine)
    with make_session_factory(engine)() as session:
        admin, _ = crud.create_racer(session, "admin", admin=True)
        tokens = {alias: crud.create_racer(session, alias)[1] for alias in RACERS}
        events = [
            crud.create_event(session, spec, admin.id).id for spec in demo_events(round_interval_s)
        ]
    engine.dispose()
    return tokens, events


def _start(name: str, args: list[str], env: dict[str, str], logs: Path) -> subprocess.Popen:
    log = (logs / f"{name}.log").open("w")
    return subprocess.Popen(
        [sys.executable, "-m", "league", *args],
        env=env,
        stdout=log,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )


@contextmanager
def _stop_signals_interrupt() -> Iterator[None]:
    """In the block, SIGTERM (``kill``, systemd, a container stop) and SIGHUP (a closed
    terminal) raise KeyboardInterrupt as Ctrl-C does, so the children are stopped the same
    way; the previous handlers come back afterwards."""
    stop_signals = (signal.SIGTERM, signal.SIGHUP)
    previous = {sig: signal.signal(sig, signal.default_int_handler) for sig in stop_signals}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _stop(processes: list[subprocess.Popen], console: Console) -> None:
    """SIGTERM to each child, up to 15 s for them all to exit, then SIGKILL to the rest
    (and their process groups); no signal interrupts this."""
    with _signals_ignored():
        _stop_children(processes, console)


@contextmanager
def _signals_ignored() -> Iterator[None]:
    stop_signals = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    previous = {sig: signal.signal(sig, signal.SIG_IGN) for sig in stop_signals}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _stop_children(processes: list[subprocess.Popen], console: Console) -> None:
    for process in processes:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + 15.0
    for process in processes:
        try:
            process.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    console.print("stopped the league's processes")


def _wait_ready(url: str, processes: list[subprocess.Popen], timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        dead = [p for p in processes if p.poll() is not None]
        if dead:
            raise RuntimeError(f"a league process exited early (code {dead[0].returncode})")
        try:
            if httpx.get(f"{url}/readyz", timeout=2.0).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.3)
    raise RuntimeError(f"the server did not become ready at {url}")


def _enter_samples(url: str, tokens: dict[str, str], events: list[int]) -> None:
    from league.client import LeagueClient

    folder = resources.files("league") / "demo_models"
    for alias, sample in zip(RACERS, SAMPLE_MODELS, strict=True):
        with resources.as_file(folder / sample) as path, LeagueClient(url, tokens[alias]) as client:
            model = client.upload_model(path, name=f"{alias}-{Path(sample).stem}")
            for event in events:
                client.enter(event, model["id"])


def _races(url: str, event: int) -> int:
    return len(httpx.get(f"{url}/api/races", params={"event": event}, timeout=10).json())


def _wait_for_results(url: str, events: list[int], console: Console, timeout: float) -> None:
    """Progress until every event has a race for each racer (head-to-model: one race)."""
    needed = {e: len(RACERS) for e in events[:-1]} | {events[-1]: 1}
    with Progress(
        TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
        TimeElapsedColumn(), console=console,
    ) as progress:  # fmt: skip
        task = progress.add_task("first races", total=sum(needed.values()))
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            done = sum(min(_races(url, e), n) for e, n in needed.items())
            progress.update(task, completed=done)
            if done >= sum(needed.values()):
                return
            time.sleep(1.0)
    console.print("[yellow]not every first race finished in time; showing what there is[/]")


def run_demo(
    out: str | Path,
    port: int = 8000,
    keep_serving: bool = True,
    round_interval_s: int = 60,
    timeout_s: float = 300.0,
) -> None:
    """Run the demo into folder ``out`` (see the module docstring)."""
    from league.cli import standings_table
    from league.client import LeagueClient

    console = Console()
    if not console.is_terminal:
        console = Console(width=160)  # logs and pipes get whole tables, not 80 columns
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    print_tracks(console, out)

    data_dir = out / "league-data"
    tokens, events = _create_league(data_dir, round_interval_s)
    logs = out / "logs"
    logs.mkdir(exist_ok=True)
    env = os.environ | {
        "SLIPSTREAM_DATA_DIR": str(data_dir.resolve()),
        "SLIPSTREAM_POLL_SECONDS": "0.5",
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
    }
    url = f"http://127.0.0.1:{port}"
    processes: list[subprocess.Popen] = []
    with _stop_signals_interrupt(), ExitStack() as stack:
        stack.callback(_stop, processes, console)
        processes.append(_start("server", ["serve", "--port", str(port)], env, logs))
        processes.append(_start("worker", ["worker", "--concurrency", "1"], env, logs))
        refused = training_refused(Settings(data_dir=data_dir))
        if refused is None:
            processes.append(_start("trainer", ["trainer"], env, logs))
        else:
            console.print(f"[yellow]no trainer:[/] {refused}")
        _wait_ready(url, processes)
        console.print(f"league running at {url} (logs in {logs})")
        _enter_samples(url, tokens, events)
        # The scheduler starts once the models are entered, so that the first
        # head-to-model round already has both of them on the grid.
        processes.append(_start("scheduler", ["scheduler"], env, logs))
        _wait_for_results(url, events, console, timeout_s)
        with LeagueClient(url) as client:
            for event in events:
                console.print(standings_table(client.event(event), client.leaderboard(event)))
        console.print(f"\nstandings and replays: [bold]{url}/[/]  (API docs: {url}/docs)")
        console.print(
            "racer tokens (shown once): "
            + ", ".join(f"{alias} {token}" for alias, token in tokens.items())
        )
        if keep_serving:
            console.print("serving until Ctrl-C ...")
            try:
                while all(p.poll() is None for p in processes):
                    time.sleep(0.5)
            except KeyboardInterrupt:
                console.print("\nCtrl-C, SIGTERM or SIGHUP: stopping")
