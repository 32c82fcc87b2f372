"""The ``slipstream`` command: one entry point that mounts every package's commands.

It sits above the five packages (tracks, arena, agents, submissions, league) and is the
only code that imports all of them; none of them imports it.
"""
