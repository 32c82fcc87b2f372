"""``python -m slipstream ...`` runs the ``slipstream`` command."""

from slipstream.cli import app

app()
