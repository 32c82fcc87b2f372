"""Database writes shared by the API, the CLI and the workers: racers, events, models, races.

Standings and ratings live in :mod:`league.ranking`, job leases and completion in
:mod:`league.jobs.queue`; an event's ruleset is frozen by :mod:`league.rulesets`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from datetime import datetime, timedelta
from typing import TYPE_CHECKING

from sqlalchemy import func, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from agents.settings import race_rules
from league.jobs.queue import evaluation_jobs
from league.models import Entry, Event, Job, Model, Race, RaceCar, Racer, utcnow
from league.rulesets import event_config
from league.schemas import EvaluationCreate, EventCreate
from league.store.base import FileStore
from league.tokens import hash_token, new_token, revoked_hash
from submissions import ModelInfo
from tracks.catalog import get_track

if TYPE_CHECKING:
    from arena.race import RaceResult


class Conflict(ValueError):
    """The request clashes with what is stored (a duplicate, a closed event)."""


class EntryLimit(Conflict):
    """The racer has as many entries in the event as a racer may."""


class QueueFull(Conflict):
    """The racer's queued evaluation jobs plus the entry's would pass their cap (retry later)."""


EVALUATION_OPEN = timedelta(hours=24)
"""How long an evaluation event stays open (its jobs race while it is)."""


class UnknownRacer(LookupError):
    """No racer has the alias asked for."""


def create_racer(session: Session, alias: str, admin: bool = False) -> tuple[Racer, str]:
    """Add a racer; return it and its API token (the only time the token is seen)."""
    token = new_token()
    racer = Racer(alias=alias, role="admin" if admin else "racer", token_hash=hash_token(token))
    session.add(racer)
    try:
        session.commit()
    except IntegrityError:
        session.rollback()
        raise Conflict(f"The alias {alias!r} is already taken.") from None
    return racer, token


def racer_by_alias(session: Session, alias: str) -> Racer:
    """The racer called ``alias``; :class:`UnknownRacer` if nobody is."""
    racer = session.scalar(select(Racer).where(Racer.alias == alias))
    if racer is None:
        raise UnknownRacer(f"No racer has the alias {alias!r}.")
    return racer


def rotate_token(session: Session, racer: Racer) -> str | None:
    """Give ``racer`` a new API token and return it (the only time it is seen); the token
    stored when ``racer`` was read stops working at once, a revoked one included.

    None when that stored token changed in between (another rotation or a revocation won):
    of two rotations racing with one token, only one gets a token back.
    """
    token = new_token()
    done = session.execute(
        update(Racer)
        .where(Racer.id == racer.id, Racer.token_hash == racer.token_hash)
        .values(token_hash=hash_token(token))
    )
    session.commit()
    return token if done.rowcount == 1 else None


def revoke_token(session: Session, racer: Racer) -> None:
    """Make ``racer``'s API token stop working; only :func:`rotate_token` gives them one again."""
    racer.token_hash = revoked_hash()
    session.commit()


def _new_event(spec: EventCreate, created_by: int | None, kind: str = "league") -> Event:
    """The event ``spec`` describes with its ruleset frozen, not yet added to a session
    (``ValueError`` with a reason if invalid)."""
    config = event_config(spec)
    opens_at = spec.opens_at or utcnow()
    if spec.closes_at is not None and spec.closes_at <= opens_at:
        raise ValueError("closes_at must be later than opens_at")
    if spec.race_type != "head_to_model":
        if spec.round_interval_s is not None:
            raise ValueError("round_interval_s is for head_to_model events only")
        if "round_bot" in spec.model_fields_set:
            raise ValueError("round_bot is for head_to_model events only")
    return Event(
        kind=kind,
        name=spec.name,
        race_type=spec.race_type,
        track=spec.track,
        direction=config.direction,
        ranking_metric=spec.ranking_metric,
        ruleset=config.ruleset(),
        ruleset_hash=config.ruleset_hash(),
        seeds=list(dict.fromkeys(spec.seeds)),
        opens_at=opens_at,
        closes_at=spec.closes_at,
        round_interval_s=spec.round_interval_s,
        round_bot=spec.round_bot,
        next_round_at=opens_at if spec.round_interval_s else None,
        created_by=created_by,
    )


def create_event(session: Session, spec: EventCreate, created_by: int | None) -> Event:
    """Freeze the ruleset and store the event (``ValueError`` with a reason if invalid)."""
    event = _new_event(spec, created_by)
    session.add(event)
    session.commit()
    return event


def evaluation_spec(model: Model, body: EvaluationCreate, now: datetime) -> EventCreate:
    """The unlisted event that evaluates ``model`` as ``body`` asks: the league's default
    ruleset for the race type on that track and direction (its obstacles or bots: the
    arena's defaults under ``body.race_settings``), seeds ``0 .. races-1``, open from
    ``now`` for :data:`EVALUATION_OPEN` (``ValueError`` for an unknown track or a race
    setting that does not fit)."""
    rules = race_rules(body.race_type, body.race_settings)
    direction = body.direction or get_track(body.track).direction
    track_name = get_track(body.track, direction).display_name
    name = f"Evaluation: {model.name} on {track_name} ({direction})"
    return EventCreate(
        name=name[:100].strip(" "),
        race_type=body.race_type,
        track=body.track,
        direction=direction,
        laps=body.laps,
        seeds=list(range(body.races)),
        opens_at=now,
        closes_at=now + EVALUATION_OPEN,
        **rules,
    )


def create_evaluation(
    session: Session,
    model: Model,
    body: EvaluationCreate,
    now: datetime,
    *,
    max_queued: int | None = None,
) -> tuple[Event, Entry, list[Job]]:
    """Store an evaluation of ``model`` (:func:`evaluation_spec`) created by its owner, with
    the model's entry and its jobs queued as :func:`enter_model` queues them, in one
    transaction: nothing is stored when it is refused. ``ValueError`` for an unknown
    track, :class:`QueueFull` past the owner's ``max_queued`` jobs waiting or running.
    """
    event = _new_event(evaluation_spec(model, body, now), model.owner_id, kind="evaluation")
    session.add(event)
    session.flush()
    entry, jobs = _enter(session, event, model, max_entries=None, max_queued=max_queued)
    return event, entry, jobs


def add_model(
    session: Session, storage: FileStore, owner: Racer, name: str, data: bytes, info: ModelInfo
) -> tuple[Model, bool]:
    """Store a validated archive and its row; return the model and whether it is new.

    The file is fsynced and renamed into place before the row commits; if the commit fails
    a file this call created is removed again, so a failure leaves neither behind. When the
    same owner's same file commits first in another request, that row is the answer.
    """
    same = select(Model).where(Model.owner_id == owner.id, Model.sha256 == info.archive_sha256)
    existing = session.scalar(same)
    if existing is not None:
        return existing, False
    sha256, created = storage.put("models", data)
    try:
        model = Model(
            owner_id=owner.id,
            name=name,
            sha256=sha256,
            size=len(data),
            info=json.loads(info.model_dump_json()),
        )
        session.add(model)
        session.commit()
    except BaseException as exc:
        session.rollback()
        winner = session.scalar(same) if isinstance(exc, IntegrityError) else None
        if winner is not None:  # the same upload raced this one and committed first
            return winner, False
        if created and session.scalar(select(Model.id).where(Model.sha256 == sha256)) is None:
            storage.remove("models", sha256)
        raise
    return model, True


def is_entered(session: Session, model_id: int) -> bool:
    """True once a model has been entered in a league event (its public fields become
    visible); its owner's evaluations do not count."""
    query = (
        select(Entry.id)
        .join(Event, Entry.event_id == Event.id)
        .where(Entry.model_id == model_id, Event.kind == "league")
        .limit(1)
    )
    return session.scalar(query) is not None


def _check_entry_limits(
    session: Session, event: Event, racer_id: int, max_entries: int, max_queued: int
) -> None:
    """Refuse an entry past the racer's caps (:class:`EntryLimit`, :class:`QueueFull`).

    Begins with a write to the racer's row, so that two entries of one racer are counted
    one after the other (a row lock on PostgreSQL, the write lock on SQLite).
    """
    session.execute(update(Racer).where(Racer.id == racer_id).values(role=Racer.role))
    entries = session.scalar(
        select(func.count(Entry.id)).where(Entry.event_id == event.id, Entry.racer_id == racer_id)
    )
    if entries >= max_entries:
        session.rollback()
        raise EntryLimit(
            f"You have {entries} entries in event {event.id}, the most one racer may have "
            f"({max_entries})."
        )
    adds = 0 if event.race_type == "head_to_model" else len(event.seeds)
    if adds == 0:
        return
    waiting = session.scalar(
        select(func.count(Job.id))
        .join(Entry, Entry.id == Job.entry_id)
        .where(Entry.racer_id == racer_id, Job.status.in_(("queued", "running")))
    )
    if waiting + adds > max_queued:
        session.rollback()
        raise QueueFull(
            f"You have {waiting} evaluation jobs waiting or running and this entry adds "
            f"{adds}; one racer may have {max_queued}. Enter again once some have raced."
        )


def enter_model(
    session: Session,
    event: Event,
    model: Model,
    now: datetime,
    *,
    max_entries: int | None = None,
    max_queued: int | None = None,
) -> tuple[Entry, list[Job]]:
    """Enter ``model`` in ``event``; queue one evaluation job per seed (none head-to-head).

    With ``max_entries`` / ``max_queued`` (the settings ``max_entries_per_racer`` and
    ``max_queued_jobs_per_racer``) an entry past the owner's caps is refused. An
    evaluation event takes no entries (:class:`Conflict`): its one entry comes with it.
    """
    if event.kind != "league":
        raise Conflict(f"Event {event.id} is a model's evaluation; it takes no entries.")
    if not event.is_open(now):
        raise Conflict(f"Event {event.id} is not open for entries.")
    return _enter(session, event, model, max_entries=max_entries, max_queued=max_queued)


def _enter(
    session: Session,
    event: Event,
    model: Model,
    *,
    max_entries: int | None,
    max_queued: int | None,
) -> tuple[Entry, list[Job]]:
    """Add the entry and its jobs past the owner's caps; commit."""
    if max_entries is not None or max_queued is not None:
        _check_entry_limits(
            session,
            event,
            model.owner_id,
            max_entries if max_entries is not None else 2**31,
            max_queued if max_queued is not None else 2**31,
        )
    entry = Entry(event_id=event.id, model_id=model.id, racer_id=model.owner_id)
    session.add(entry)
    try:
        session.flush()
    except IntegrityError:
        session.rollback()
        raise Conflict(f"Model {model.id} is already entered in event {event.id}.") from None
    jobs = []
    if event.race_type != "head_to_model":
        jobs = [Job(**row) for row in evaluation_jobs(event.id, entry.id, event.seeds)]
        session.add_all(jobs)
    bump_results_version(session, event.id)
    session.commit()
    return entry, jobs


def record_race(
    session: Session,
    storage: FileStore,
    event: Event,
    result: RaceResult,
    entries: Mapping[str, Entry],
    *,
    job_id: int | None = None,
    commit: bool = True,
) -> Race:
    """Store a finished race: config, per-car results (ms) and racing metrics, the replay file
    (trace, bots, obstacles and the overtake and contact events), the job it ran for. A car
    taken out of the race for a model fault keeps its reason (``RaceCar.dnf_reason``, and
    the summary's ``dnf_reasons`` by car name, which the race's API result shows).

    ``entries`` maps car names to the entries that drove them (bots have none). The job's
    own state is the queue's (:func:`league.jobs.queue.claim_done`). With ``commit=False`` the
    rows join the caller's transaction (workers commit once).
    """
    trace = json.dumps(result.replay_data(), separators=(",", ":")).encode()
    trace_sha, _ = storage.put("traces", trace)
    race = Race(
        event_id=event.id,
        job_id=job_id,
        ruleset_hash=result.config.ruleset_hash(),
        seed=result.config.seed,
        config=json.loads(result.config.to_json()),
        summary={
            "finish_order": result.finish_order,
            "duration": result.duration,
            "steps": result.steps,
            "dnf_reasons": {c.name: c.dnf_reason for c in result.cars if c.dnf_reason},
        },
        trace_sha256=trace_sha,
    )
    for car in result.cars:
        entry = entries.get(car.name)
        race.cars.append(
            RaceCar(
                entry_id=entry.id if entry else None,
                model_id=entry.model_id if entry else None,
                car_name=car.name,
                status=car.status,
                laps=car.laps,
                lap_times_ms=[_ms(t) for t in car.lap_times],
                best_ms=_ms(car.best_lap),
                average_ms=_ms(car.average_lap),
                total_ms=_ms(car.total_time),
                penalty_ms=_ms(car.penalty_seconds) or 0,
                off_track_count=car.off_track_count,
                crash_count=car.crash_count,
                reset_count=car.reset_count,
                distance_m=car.distance,
                finish_position=car.finish_position,
                overtakes=car.overtakes,
                times_overtaken=car.times_overtaken,
                at_fault_collisions=car.at_fault_collisions,
                laps_led=car.laps_led,
                gap_to_winner_ms=_ms(car.gap_to_winner),
                dnf_reason=car.dnf_reason,
            )
        )
    session.add(race)
    bump_results_version(session, event.id)
    if commit:
        session.commit()
    return race


def bump_results_version(session: Session, event_id: int) -> None:
    """Mark the event's results as changed (its cached leaderboards go stale).

    Joins the caller's transaction; every write that changes a leaderboard calls this.
    """
    session.execute(
        update(Event).where(Event.id == event_id).values(results_version=Event.results_version + 1)
    )


def _ms(seconds: float | None) -> int | None:
    return None if seconds is None else round(seconds * 1000)
