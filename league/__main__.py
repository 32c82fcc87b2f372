"""``python -m league ...`` runs the league's own commands, as ``slipstream league ...``."""

from league.cli import app

app()
