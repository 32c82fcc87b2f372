"""Training jobs on the league server: specs, sandbox, trainer."""
