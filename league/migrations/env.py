"""Alembic environment: runs on the connection handed over by ``league.migrations``."""

from __future__ import annotations

from alembic import context

from league.models import Base


def run() -> None:
    """Run migrations online on the caller's connection (batch mode for SQLite)."""
    connection = context.config.attributes["connection"]
    context.configure(
        connection=connection,
        target_metadata=Base.metadata,
        render_as_batch=connection.dialect.name == "sqlite",
        compare_type=True,
    )
    with context.begin_transaction():
        context.run_migrations()


run()
