"""The uvicorn configuration of every league server: the one place that says what a
connection may cost (head size, header count and timeout, keep-alive, connection cap).

``slipstream league serve`` builds its server with :func:`server_config`; so should
anything else that serves the league (tests, benchmarks).
"""

from __future__ import annotations

from typing import Any

import uvicorn

from league.http.bounded_protocol import HeadLimits
from league.settings import Settings

HTTP_PROTOCOL = "league.http.bounded_protocol:BoundedHttpToolsProtocol"
"""uvicorn's httptools protocol with each request head bounded before it is parsed."""


class LeagueConfig(uvicorn.Config):
    """``uvicorn.Config`` that also carries the :class:`HeadLimits` the protocol enforces
    (a module-level class, so it travels to ``--workers`` processes)."""

    def __init__(self, app: Any, *, head_limits: HeadLimits, **options: Any) -> None:
        super().__init__(app, **options)
        self.head_limits = head_limits


def connection_options(settings: Settings) -> dict[str, Any]:
    """The uvicorn keyword options that bound connections, from ``settings``."""
    return {
        "http": HTTP_PROTOCOL,
        "h11_max_incomplete_event_size": settings.max_header_bytes,  # if run with h11
        "timeout_keep_alive": settings.keep_alive_seconds,
        "limit_concurrency": settings.max_connections,
    }


def server_config(app: Any, settings: Settings, **options: Any) -> LeagueConfig:
    """A uvicorn config serving ``app`` (an app, or an import string with ``factory=True``)
    with the connection bounds of ``settings``; ``options`` are any other uvicorn options
    (host, port, log_level, access_log, workers...)."""
    return LeagueConfig(
        app, head_limits=HeadLimits.of(settings), **connection_options(settings), **options
    )
