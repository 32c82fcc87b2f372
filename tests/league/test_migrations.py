"""Migrations: an empty database upgrades to head, an older revision upgrades with its data
kept, the ORM matches the migrations, and /readyz notices an unmigrated database."""

from __future__ import annotations

from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import inspect, text

from league.db import make_engine
from league.http.app import create_app
from league.migrations import alembic_config, current_revision, head_revision, is_current, upgrade
from league.models import Base
from league.settings import Settings
from tests.league.conftest import Database, ServerThread, free_port

ALL_TABLES = {
    "racers",
    "models",
    "events",
    "entries",
    "jobs",
    "races",
    "race_cars",
    "ratings",
    "training_jobs",
    "training_events",
}


def _tables(engine) -> set[str]:
    return set(inspect(engine).get_table_names()) - {"alembic_version"}


def test_upgrade_from_previous_revision_keeps_data(database: Database) -> None:
    engine = make_engine(database.url)
    upgrade(engine, "0001")
    assert _tables(engine) == {"racers", "models"}
    with engine.begin() as conn:
        conn.execute(
            text(
                "INSERT INTO racers (id, alias, role, token_hash, created_at) "
                "VALUES (1, 'old', 'racer', :h, CURRENT_TIMESTAMP)"
            ),
            {"h": "0" * 64},
        )
        conn.execute(
            text(
                "INSERT INTO models (id, owner_id, name, sha256, size, info, created_at) "
                "VALUES (1, 1, 'm', :s, 10, '{}', CURRENT_TIMESTAMP)"
            ),
            {"s": "a" * 64},
        )
    assert not is_current(engine)
    upgrade(engine)
    assert is_current(engine) and _tables(engine) == ALL_TABLES
    with engine.connect() as conn:
        assert conn.execute(text("SELECT alias FROM racers")).scalar_one() == "old"
        assert current_revision(conn) == head_revision()
    engine.dispose()


def test_models_match_migrations_and_downgrade_upgrade_again(database: Database) -> None:
    engine = make_engine(database.url)
    upgrade(engine)
    with engine.connect() as conn:
        context = MigrationContext.configure(conn, opts={"compare_type": True})
        assert compare_metadata(context, Base.metadata) == []
    with engine.begin() as conn:
        conn.execute(text("DELETE FROM models"))
        conn.execute(text("DELETE FROM racers"))
        command.downgrade(alembic_config(conn), "base")
    assert _tables(engine) == set()
    upgrade(engine)  # an empty database
    assert _tables(engine) == ALL_TABLES and is_current(engine)
    engine.dispose()


def test_race_results_stored_before_racing_metrics_upgrade_with_zero_counts(
    database: Database,
) -> None:
    engine = make_engine(database.url)
    with engine.begin() as conn:
        command.downgrade(alembic_config(conn), "base")
    upgrade(engine, "0003")
    with engine.begin() as conn:
        conn.execute(
            text(
                "INSERT INTO events (id, name, race_type, track, direction, ranking_metric,"
                " ruleset, ruleset_hash, seeds, opens_at, results_version, created_at)"
                " VALUES (1, 'old cup', 'head_to_model', 'beginner_loop', 'ccw', 'total',"
                " '{}', :h, '[0]', CURRENT_TIMESTAMP, 0, CURRENT_TIMESTAMP)"
            ),
            {"h": "0" * 64},
        )
        conn.execute(
            text(
                "INSERT INTO races (id, event_id, ruleset_hash, seed, config, summary, created_at)"
                " VALUES (1, 1, :h, 0, '{}', '{}', CURRENT_TIMESTAMP)"
            ),
            {"h": "0" * 64},
        )
        conn.execute(
            text(
                "INSERT INTO race_cars (id, race_id, car_name, status, laps, lap_times_ms,"
                " penalty_ms, off_track_count, crash_count, reset_count, distance_m,"
                " finish_position) VALUES (1, 1, 'car0', 'finished', 1, '[9000]', 0, 0, 2, 2,"
                " 17.5, 1)"
            )
        )
    upgrade(engine)
    with engine.connect() as conn:
        row = conn.execute(
            text(
                "SELECT crash_count, overtakes, times_overtaken, at_fault_collisions, laps_led,"
                " gap_to_winner_ms FROM race_cars"
            )
        ).one()
    assert tuple(row) == (2, 0, 0, 0, 0, None)
    with engine.begin() as conn:
        command.downgrade(alembic_config(conn), "0003")
    assert "overtakes" not in {c["name"] for c in inspect(engine).get_columns("race_cars")}
    with engine.begin() as conn:
        for table in ("race_cars", "races", "events"):
            conn.execute(text(f"DELETE FROM {table}"))
    upgrade(engine)
    engine.dispose()


def test_readyz_refuses_an_unmigrated_database(tmp_path) -> None:
    app = create_app(Settings(data_dir=tmp_path, rate_limit_per_second=0))
    with ServerThread(app, free_port()) as server:
        import httpx

        response = httpx.get(f"{server.url}/readyz")
    assert response.status_code == 503 and "migrations" in response.json()["detail"]
