"""``python -m league ...`` runs the ``slipstream`` command (used for child processes)."""

from league.cli import app

app()
