"""``slipstream league``: serve the league, create racers and events, submit, standings."""

from __future__ import annotations

import contextlib
import json
import signal
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table
from rich.text import Text

if TYPE_CHECKING:
    import uvicorn
    from sqlalchemy.orm import Session

    from league.client import LeagueClient, LeagueError
    from league.settings import Settings

app = typer.Typer(help="The league server and its client commands.", no_args_is_help=True)
console = Console()
DEFAULT_SERVER = "http://127.0.0.1:8000"

DataDir = Annotated[
    Path | None,
    typer.Option(help="Data directory (default: SLIPSTREAM_DATA_DIR or ./slipstream-data)."),
]
Server = Annotated[str, typer.Option(envvar="SLIPSTREAM_SERVER", help="League server URL.")]
Token = Annotated[
    str | None, typer.Option(envvar="SLIPSTREAM_TOKEN", help="Your API token.", show_default=False)
]


def _settings(data_dir: Path | None) -> Settings:
    from league.settings import Settings

    return Settings(data_dir=data_dir) if data_dir is not None else Settings()


def _fail(message: object) -> typer.Exit:
    """Print ``message`` in red, literally (never as markup); the exit to raise (status 1)."""
    console.print(Text(str(message), style="red"))
    return typer.Exit(1)


def _migrated_session(data_dir: Path | None) -> Session:
    from league.db import make_engine, make_session_factory
    from league.migrations import upgrade

    settings = _settings(data_dir)
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    engine = make_engine(settings.db_url, settings.sqlite_busy_timeout_ms)
    upgrade(engine)
    return make_session_factory(engine)()


@app.command()
def serve(
    host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="Port to listen on.")] = 8000,
    data_dir: DataDir = None,
    workers: Annotated[
        int, typer.Option(min=1, help="Server processes (uvicorn workers) sharing the port.")
    ] = 1,
    access_log: Annotated[bool, typer.Option(help="Log every request.")] = True,
) -> None:
    """Run the database migrations, then serve the API (docs at /docs).

    With ``--workers N`` uvicorn runs N processes; each builds the app from the
    ``SLIPSTREAM_*`` environment (``--data-dir`` is passed on as ``SLIPSTREAM_DATA_DIR``).
    """
    import os

    from league.db import make_engine
    from league.http.app import create_app
    from league.http.server_options import server_config
    from league.migrations import upgrade

    settings = _settings(data_dir)
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    engine = make_engine(settings.db_url, settings.sqlite_busy_timeout_ms)
    upgrade(engine)
    engine.dispose()
    options = {"host": host, "port": port, "log_level": "info", "access_log": access_log}
    if workers == 1:
        _run_server(server_config(create_app(settings), settings, **options))
        return
    if data_dir is not None:
        os.environ["SLIPSTREAM_DATA_DIR"] = str(data_dir.resolve())
    app_factory = "league.http.app:create_app"
    _run_server(server_config(app_factory, settings, factory=True, workers=workers, **options))


def hangup_as_terminate() -> None:
    """Make SIGHUP (a closed terminal, ``kill -HUP``) stop this process as SIGTERM does.

    Every long-running league command stops its children and itself gracefully on SIGTERM,
    as on Ctrl-C; this extends that to SIGHUP, whose default would kill the process alone.
    """
    signal.signal(signal.SIGHUP, lambda *_: signal.raise_signal(signal.SIGTERM))


def _run_server(config: uvicorn.Config) -> None:
    """Serve ``config`` until SIGINT, SIGTERM or SIGHUP (uvicorn's ``run``, except that
    SIGHUP stops ``--workers`` processes instead of restarting them)."""
    import uvicorn
    from uvicorn.supervisors import Multiprocess

    class StopOnHangup(Multiprocess):
        def handle_hup(self) -> None:
            self.handle_term()

    hangup_as_terminate()
    if config.workers > 1:
        StopOnHangup(config, sockets=[config.bind_socket()]).run()
        return
    server = uvicorn.Server(config)
    with contextlib.suppress(KeyboardInterrupt):
        server.run()
    if not server.started:
        raise typer.Exit(3)  # uvicorn's exit status when a server fails to start


@app.command("create-racer")
def create_racer(
    alias: Annotated[str, typer.Argument(help="The racer's alias (2-32 letters/digits/_.-).")],
    admin: Annotated[bool, typer.Option("--admin", help="Make them a league admin.")] = False,
    data_dir: DataDir = None,
) -> None:
    """Create a racer directly in the database and print their API token (shown once)."""
    from pydantic import ValidationError

    from league import crud
    from league.schemas import RacerCreate

    try:
        spec = RacerCreate(alias=alias, admin=admin)
    except ValidationError as exc:
        raise typer.BadParameter(exc.errors()[0]["msg"], param_hint="ALIAS") from None
    with _migrated_session(data_dir) as session:
        try:
            racer, token = crud.create_racer(session, spec.alias, spec.admin)
        except crud.Conflict as exc:
            raise _fail(exc) from None
    console.print(f"racer [bold]{escape(racer.alias)}[/bold] (id {racer.id}, {racer.role})")
    console.print("API token (shown once, keep it safe):")
    typer.echo(token)


AliasArgument = Annotated[str, typer.Argument(help="The racer's alias.")]


@app.command("rotate-token")
def rotate_token(alias: AliasArgument, data_dir: DataDir = None) -> None:
    """Give a racer a new API token (printed once); the old or revoked one stops working."""
    from league import crud

    with _migrated_session(data_dir) as session:
        try:
            racer = crud.racer_by_alias(session, alias)
        except crud.UnknownRacer as exc:
            raise _fail(exc) from None
        token = crud.rotate_token(session, racer)
    if token is None:
        raise _fail(f"The token of {alias!r} changed meanwhile; nothing was done, run this again.")
    console.print(f"racer [bold]{escape(alias)}[/bold]: the old API token no longer works")
    console.print("new API token (shown once, keep it safe):")
    typer.echo(token)


@app.command("revoke-token")
def revoke_token(alias: AliasArgument, data_dir: DataDir = None) -> None:
    """Make a racer's API token stop working; only rotate-token gives them a new one."""
    from league import crud

    with _migrated_session(data_dir) as session:
        try:
            crud.revoke_token(session, crud.racer_by_alias(session, alias))
        except crud.UnknownRacer as exc:
            raise _fail(exc) from None
    console.print(f"racer [bold]{escape(alias)}[/bold]: API token revoked")
    console.print(f"give them a new one with: slipstream league rotate-token {escape(alias)}")


def _read_ruleset(path: Path) -> dict:
    text = path.read_text()
    if path.suffix.lower() in (".yaml", ".yml"):
        import yaml

        return yaml.safe_load(text) or {}
    return json.loads(text)


@app.command("create-event")
def create_event(
    name: Annotated[str | None, typer.Option(help="Event name (or in the ruleset file).")] = None,
    ruleset: Annotated[
        Path | None, typer.Option("--ruleset", "-f", help="YAML or JSON file of event fields.")
    ] = None,
    race_type: Annotated[str | None, typer.Option(help="time_trial, object_avoidance, ...")] = None,
    track: Annotated[str | None, typer.Option(help="Track name.")] = None,
    direction: Annotated[str | None, typer.Option(help="ccw or cw.")] = None,
    laps: Annotated[int | None, typer.Option(help="Laps per race.")] = None,
    metric: Annotated[str | None, typer.Option(help="total, best or average.")] = None,
    seeds: Annotated[str | None, typer.Option(help="Evaluation seeds, e.g. 0,1,2.")] = None,
    data_dir: DataDir = None,
) -> None:
    """Create an event directly in the database; options override the ruleset file."""
    from pydantic import ValidationError

    from arena.config import describe_validation_error
    from league import crud
    from league.schemas import EventCreate

    fields = _read_ruleset(ruleset) if ruleset else {}
    given = {
        "name": name,
        "race_type": race_type,
        "track": track,
        "direction": direction,
        "laps": laps,
        "ranking_metric": metric,
        "seeds": [int(s) for s in seeds.split(",")] if seeds else None,
    }
    fields.update({k: v for k, v in given.items() if v is not None})
    try:
        spec = EventCreate.model_validate(fields)
        with _migrated_session(data_dir) as session:
            event = crud.create_event(session, spec, created_by=None)
    except ValidationError as exc:
        raise _fail(describe_validation_error(exc)) from None
    except ValueError as exc:
        raise _fail(exc) from None
    where = f": {event.name} ({event.race_type}, {event.track})"
    console.print(Text.assemble("event ", (str(event.id), "bold"), where))
    console.print(f"ruleset hash {event.ruleset_hash}")


@app.command()
def submit(
    model: Annotated[Path, typer.Argument(exists=True, dir_okay=False, help="Model archive.")],
    event: Annotated[int, typer.Option("--event", help="Event id to enter.")],
    server: Server = DEFAULT_SERVER,
    token: Token = None,
    name: Annotated[str | None, typer.Option(help="Model name on the server.")] = None,
) -> None:
    """Validate a model locally, upload it and enter it in an event."""
    from league.client import LeagueClient, LeagueError
    from submissions import validate

    if not token:
        console.print("[red]an API token is needed: --token or SLIPSTREAM_TOKEN[/red]")
        raise typer.Exit(2)
    report = validate(model)
    if not report.ok:
        console.print(Text(f"{model} fails validation; nothing was uploaded:", style="red"))
        for problem in report.problems:
            console.print(Text(f"  - {problem}"))
        raise typer.Exit(1)
    try:
        with LeagueClient(server, token) as client:
            record = client.upload_model(model, name)
            entry = client.enter(event, record["id"])
    except LeagueError as exc:
        console.print(Text(f"the server refused: {exc.message}", style="red"))
        for problem in exc.problems:
            console.print(Text(f"  - {problem.get('field')}: {problem.get('message')}"))
        raise typer.Exit(1) from None
    console.print(Text(f"model {record['id']} ({record['name']}) entered in event {event}"))
    console.print(f"entry {entry['entry_id']}; jobs queued: {entry['job_ids']}")


def _seconds(ms: int | None) -> str:
    return "-" if ms is None else f"{ms / 1000:.3f}"


@app.command()
def standings(
    event: Annotated[int, typer.Argument(help="Event id.")],
    server: Server = DEFAULT_SERVER,
) -> None:
    """Print an event's leaderboard as a table."""
    from league.client import LeagueClient, LeagueError

    try:
        with LeagueClient(server) as client:
            info = client.event(event)
            board = client.leaderboard(event)
    except LeagueError as exc:
        raise _fail(exc.message) from None
    console.print(standings_table(info, board))


@app.command()
def scheduler(data_dir: DataDir = None) -> None:
    """Run the scheduler daemon: jobs for entries, head-to-model rounds, event closing."""
    import logging

    from league.db import make_engine
    from league.jobs.scheduler import Scheduler
    from league.migrations import upgrade

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    settings = _settings(data_dir)
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    upgrade(make_engine(settings.db_url, settings.sqlite_busy_timeout_ms))
    hangup_as_terminate()
    Scheduler(settings).run_forever()


@app.command()
def worker(
    concurrency: Annotated[int, typer.Option(min=1, help="Worker processes (one race each).")] = 1,
    data_dir: DataDir = None,
) -> None:
    """Run evaluation workers: lease jobs, race them sandboxed, record results."""
    import logging
    import os

    from league.jobs.worker import supervise

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    if data_dir is not None:
        os.environ["SLIPSTREAM_DATA_DIR"] = str(data_dir)
    hangup_as_terminate()
    supervise(concurrency)


@app.command()
def trainer(
    data_dir: DataDir = None,
    name: Annotated[str | None, typer.Option(help="Trainer name (default: host-pid).")] = None,
) -> None:
    """Run a trainer: lease training jobs, train them sandboxed, store their models."""
    import logging

    from league.db import make_engine
    from league.migrations import upgrade
    from league.training.launch import training_refused
    from league.training.trainer import Trainer

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    settings = _settings(data_dir)
    refused = training_refused(settings)
    if refused:
        raise _fail(refused)
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    upgrade(make_engine(settings.db_url, settings.sqlite_busy_timeout_ms))
    hangup_as_terminate()
    Trainer(settings, name).run_forever()


def standings_table(info: dict, board: dict) -> Table:
    """An event's leaderboard (as the API returns it) as a Rich table; names and aliases
    are shown literally, never read as Rich markup."""
    rated = board["race_type"] == "head_to_model"
    title = f"{info['name']} ({info['race_type']}, {board['ranking_metric']} time)"
    table = Table(title=Text(title))
    columns = ["rank", "alias", "laps", "best s", "average s", "total s", "off-track"]
    columns += ["collisions", "at fault", "resets", "score s", "submissions"]
    columns += ["overtakes", "laps led", "mu", "sigma", "rating"] if rated else []
    for column in columns:
        table.add_column(column, justify="left" if column == "alias" else "right")
    for row in board["rows"]:
        cells = [
            str(row["rank"]),
            Text(row["alias"]),
            str(row["lap_count"]),
            _seconds(row["best_lap_ms"]),
            _seconds(row["average_lap_ms"]),
            _seconds(row["total_time_ms"]),
            str(row["off_track_count"]),
            str(row["collision_count"]),
            str(row["at_fault_collisions"]),
            str(row["reset_count"]),
            _seconds(row["ranking_score_ms"]),
            str(row["submission_count"]),
        ]
        if rated:
            cells += [str(row["overtakes"]), str(row["laps_led"])]
            cells += [f"{row[k]:.2f}" if row[k] is not None else "-" for k in ("mu", "sigma")]
            cells.append(f"{row['ordinal']:.2f}" if row["ordinal"] is not None else "-")
        table.add_row(*cells)
    return table


# Training jobs on the league's trainers (``/api/training-jobs``): train, jobs, stop-training.


def _described(name: str) -> str:
    """The help of ``slipstream train``'s option for the settings field ``name``."""
    from agents.settings import TrainSettings

    return TrainSettings.model_fields[name].description or ""


def _train_option(name: str) -> typer.models.OptionInfo:
    return typer.Option(help=_described(name), show_default=False, rich_help_panel="Training")


def _need_token(token: str | None) -> str:
    if not token:
        console.print("[red]an API token is needed: --token or SLIPSTREAM_TOKEN[/red]")
        raise typer.Exit(2)
    return token


def _refused(exc: LeagueError) -> typer.Exit:
    """Print a server refusal (and, for a 429, when to try again); the exit (status 1)."""
    console.print(Text(f"the server refused: {exc.message}", style="red"))
    for problem in exc.problems:
        console.print(Text(f"  - {problem.get('field')}: {problem.get('message')}"))
    if exc.status == 429 and exc.retry_after is not None:
        console.print(Text(f"try again {_after(exc.retry_after)}", style="red"))
    return typer.Exit(1)


def _after(seconds: int) -> str:
    """When a ``Retry-After`` of ``seconds`` ends, in words."""
    from datetime import UTC, datetime, timedelta

    if seconds < 120:
        return f"in {seconds} s"
    if seconds < 2 * 3600:
        return f"in {round(seconds / 60)} min"
    when = datetime.now(UTC) + timedelta(seconds=seconds)
    return f"after {when:%Y-%m-%d %H:%M} UTC"


def _unreachable(server: str, exc: Exception) -> typer.Exit:
    return _fail(f"cannot reach the league server at {server}: {exc}")


def _reward_source(spec: str) -> str:
    """The source of ``--reward-fn``: a ``.py`` file, or a bundled sample's file."""
    import os

    from agents.rewards import bundled_samples

    path = Path(spec)
    if spec.endswith(".py") or os.sep in spec or path.exists():
        if not path.is_file():
            raise typer.BadParameter(f"no such file: {spec}", param_hint="--reward-fn")
        try:
            return path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise typer.BadParameter(
                f"cannot read {spec}: {exc}", param_hint="--reward-fn"
            ) from None
    samples = bundled_samples()
    if spec not in samples:
        raise typer.BadParameter(
            f"{spec!r} is neither a .py file nor a bundled sample ({', '.join(samples)})",
            param_hint="--reward-fn",
        )
    return samples[spec].read_text(encoding="utf-8")


def _default_reward(recipe: str | None) -> str:
    """``--reward-fn`` when not given: the recipe's, else ``slipstream train``'s default."""
    from agents.recipes import RECIPES
    from agents.settings import TrainSettings

    if recipe in RECIPES and "reward_fn" in RECIPES[recipe].options:
        return str(RECIPES[recipe].options["reward_fn"])
    return str(TrainSettings.model_fields["reward_fn"].default)


def _hyperparameters_of(path: Path) -> dict:
    """The DeepRacer hyperparameters in ``path`` that training reads (others warned about)."""
    from agents.hyperparameters import Hyperparameters

    try:
        _, ignored = Hyperparameters.read(path)
    except (OSError, ValueError) as exc:
        raise typer.BadParameter(str(exc), param_hint="--hyperparameters") from None
    if ignored:
        console.print(
            Text(f"warning: {path}: ignoring {', '.join(ignored)} (not DeepRacer hyperparameters)")
        )
    data = json.loads(path.read_text(encoding="utf-8"))
    return {key: value for key, value in data.items() if key not in ignored}


@app.command("train")
def train_on_server(
    name: Annotated[str, typer.Option(help="The trained model's name on the server.")],
    minutes: Annotated[
        float,
        typer.Option(
            help="Training budget in minutes (at most the league's training_max_minutes)."
        ),
    ],
    server: Server = DEFAULT_SERVER,
    token: Token = None,
    reward_fn: Annotated[
        str | None,
        typer.Option(
            help="Reward-function .py file or bundled sample name (default: the recipe's, "
            "else follow_center_line); its source is sent to the server.",
            show_default=False,
        ),
    ] = None,
    track: Annotated[str | None, _train_option("track")] = None,
    direction: Annotated[str | None, _train_option("direction")] = None,
    race_type: Annotated[str | None, _train_option("race_type")] = None,
    sensors: Annotated[str | None, _train_option("sensors")] = None,
    action_space: Annotated[str | None, _train_option("action_space")] = None,
    network: Annotated[str | None, _train_option("network")] = None,
    critic: Annotated[str | None, _train_option("critic")] = None,
    teacher: Annotated[str | None, _train_option("teacher")] = None,
    seed: Annotated[int | None, _train_option("seed")] = None,
    eval_every: Annotated[int | None, _train_option("eval_every")] = None,
    eval_time_limit: Annotated[float | None, _train_option("eval_time_limit")] = None,
    selfplay: Annotated[str | None, _train_option("selfplay")] = None,
    recipe: Annotated[
        str | None,
        typer.Option(help="Start from a named recipe (slipstream train --list-recipes)."),
    ] = None,
    hyperparameters: Annotated[
        Path | None,
        typer.Option(
            exists=True,
            dir_okay=False,
            help="DeepRacer hyperparameters.json (wins over a recipe's).",
        ),
    ] = None,
    clone: Annotated[
        int | None,
        typer.Option(help="Start from the run of one of your training jobs (its id)."),
    ] = None,
    resume: Annotated[
        int | None,
        typer.Option(
            help="Continue the run of one of your training jobs (its id) for --minutes more, "
            "with its settings (and its reward, unless --reward-fn is given)."
        ),
    ] = None,
    wait: Annotated[
        bool, typer.Option("--wait", help="Follow the job's progress until it ends.")
    ] = False,
) -> None:
    """Train a model on the league's trainers, as ``slipstream train`` would here; the
    model stays on the server, ready to enter events."""
    import httpx

    from league.client import LeagueClient, LeagueError

    token = _need_token(token)
    given = {
        "track": track,
        "direction": direction,
        "race_type": race_type,
        "sensors": sensors,
        "action_space": action_space,
        "network": network,
        "critic": critic,
        "teacher": teacher,
        "seed": seed,
        "eval_every": eval_every,
        "eval_time_limit": eval_time_limit,
        "selfplay": selfplay,
    }
    body: dict = {
        "name": name,
        "options": {key: value for key, value in given.items() if value is not None},
        "minutes": minutes,
    }
    if resume is None or reward_fn is not None:
        body["reward_source"] = _reward_source(reward_fn or _default_reward(recipe))
    if recipe is not None:
        body["recipe"] = recipe
    if hyperparameters is not None:
        body["hyperparameters"] = _hyperparameters_of(hyperparameters)
    if clone is not None:
        body["clone_of"] = clone
    if resume is not None:
        body["resume_of"] = resume
    try:
        with LeagueClient(server, token) as client:
            job = client.create_training_job(body)
            console.print(
                Text.assemble(
                    "training job ", (str(job["id"]), "bold"), f" ({job['name']}): {job['status']}"
                )
            )
            if not wait:
                return
            _follow(client, job["id"])
    except LeagueError as exc:
        raise _refused(exc) from None
    except httpx.HTTPError as exc:
        raise _unreachable(server, exc) from None


def _iteration_line(data: dict) -> Text:
    """One iteration of a training job, as ``slipstream train`` shows it."""
    line = f"it {data.get('iteration')}  reward {data.get('mean_reward', 0.0):.1f}  "
    line += f"progress {data.get('mean_progress', 0.0):.0f}%"
    evaluation = data.get("eval")
    if evaluation:
        best = evaluation.get("best_lap")
        line += f"  eval {evaluation.get('laps', 0)} laps"
        line += f", best lap {best:.3f} s" if best is not None else ""
        line += f" ({evaluation.get('progress', 0.0):.0f}%)"
    return Text(line)


def _follow(client: LeagueClient, job_id: int) -> None:
    """Print a job's events until it ends, then how it ended (exit 1 unless done or
    stopped)."""
    try:
        for event, data in client.training_events(job_id):
            if event == "iteration":
                console.print(_iteration_line(data))
            elif event == "log":
                console.print(Text(str(data.get("line", "")), style="dim"))
            elif event == "status":
                error = data.get("error")
                line = f"[{data.get('status')}]" + (f" {error}" if error else "")
                console.print(Text(line, style="dim"))
    except KeyboardInterrupt:
        console.print(
            Text(
                f"stopped following; training job {job_id} goes on "
                f"(stop it with: slipstream league stop-training {job_id})"
            )
        )
        raise typer.Exit(130) from None
    job = client.training_job(job_id)
    status = job["status"]
    if status == "failed":
        raise _fail(f"training job {job_id} failed: {job.get('error') or 'no reason given'}")
    if status not in ("done", "stopped"):
        raise _fail(f"the event stream ended but training job {job_id} is {status}")
    model = f"model {job['model_id']}" if job.get("model_id") is not None else "no model"
    best = job.get("best_lap_ms")
    lap = f"best lap {best / 1000:.3f} s" if best is not None else "no evaluation lap"
    console.print(Text.assemble((status, "bold green"), f": {model}, {lap}"))


JOBS_SHOWN_ENDED = 10
"""Ended jobs ``league jobs`` shows without ``--all-statuses`` (the newest)."""
_STATUS_STYLE = {"queued": "yellow", "running": "cyan", "done": "green", "failed": "red"}


@app.command()
def jobs(
    server: Server = DEFAULT_SERVER,
    token: Token = None,
    all_statuses: Annotated[
        bool,
        typer.Option(
            "--all-statuses",
            help=f"Show every job (default: queued and running ones, and the "
            f"{JOBS_SHOWN_ENDED} newest that ended).",
        ),
    ] = False,
) -> None:
    """Your training jobs as a table, and your training quota this month."""
    import httpx

    from league.client import LeagueClient, LeagueError

    token = _need_token(token)
    try:
        with LeagueClient(server, token) as client:
            listed = client.training_jobs()
            quota = client.training_quota()
    except LeagueError as exc:
        raise _refused(exc) from None
    except httpx.HTTPError as exc:
        raise _unreachable(server, exc) from None
    ended = [job["id"] for job in listed if job["status"] not in ("queued", "running")]
    hidden = set() if all_statuses else set(ended[JOBS_SHOWN_ENDED:])
    console.print(training_jobs_table([job for job in listed if job["id"] not in hidden]))
    if hidden:
        console.print(f"{len(hidden)} older ended jobs not shown (--all-statuses shows them)")
    console.print(quota_line(quota))


def training_jobs_table(listed: list[dict]) -> Table:
    """Training jobs (as the API lists them) as a Rich table; names shown literally."""
    from rich import box

    title = "training jobs (budget and used: minutes)"
    table = Table(title=title, box=box.SIMPLE_HEAD, pad_edge=False, padding=(0, 1))
    columns = ["id", "name", "status", "budget", "used", "best s", "model", "created"]
    for column in columns:
        left = column in ("name", "status")
        table.add_column(
            column,
            justify="left" if left else "right",
            no_wrap=column != "name",
            min_width=8 if column == "name" else None,
        )
    for job in listed:
        status = Text(job["status"], style=_STATUS_STYLE.get(job["status"], ""))
        if job.get("stop_requested") and job["status"] == "running":
            status.append(" (stopping)")
        table.add_row(
            str(job["id"]),
            Text(job["name"]),
            status,
            f"{job['minutes']:g}",
            f"{job['compute_minutes']:.1f}",
            _seconds(job.get("best_lap_ms")),
            "-" if job.get("model_id") is None else str(job["model_id"]),
            _when(job["created_at"]),
        )
    return table


def _when(iso: str) -> str:
    from datetime import UTC, datetime

    try:
        moment = datetime.fromisoformat(iso).astimezone(UTC)
    except (TypeError, ValueError):
        return str(iso)
    return f"{moment:%Y-%m-%d %H:%M}"


def quota_line(quota: dict) -> Text:
    """The ``/quota`` answer in one line."""
    used, allowed = quota["minutes_used"], quota["minutes_per_month"]
    return Text(
        f"training quota: {used:.1f} of {allowed:g} minutes used this month "
        f"(queued and running jobs count in full); resets {_when(quota['resets_at'])} UTC"
    )


@app.command("stop-training")
def stop_training(
    job_id: Annotated[int, typer.Argument(help="Training job id (see: slipstream league jobs).")],
    server: Server = DEFAULT_SERVER,
    token: Token = None,
) -> None:
    """Stop one of your training jobs: a queued one at once, a running one within a
    heartbeat, keeping the model trained so far."""
    import httpx

    from league.client import LeagueClient, LeagueError

    token = _need_token(token)
    try:
        with LeagueClient(server, token) as client:
            job = client.stop_training_job(job_id)
    except LeagueError as exc:
        raise _refused(exc) from None
    except httpx.HTTPError as exc:
        raise _unreachable(server, exc) from None
    status = job["status"]
    if status == "running":
        console.print(
            f"training job {job_id}: stop requested; it stops within a heartbeat, "
            "keeping the model trained so far"
        )
    else:
        console.print(f"training job {job_id}: {status}")
