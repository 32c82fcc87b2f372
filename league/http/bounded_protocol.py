"""uvicorn's httptools protocol with bounds on each request head, enforced before parsing.

Stock uvicorn puts no limit on a request's line and headers: httptools joins a header's
pieces by concatenation, so one header of N bytes costs time in N squared on the event
loop, and an unfinished head is held until the client leaves; no timer runs before the
first response either. This protocol feeds the parser at most ``max_bytes`` of one head
(then answers 431 and closes), counts its header fields (over ``max_count``: 431), and
closes a connection whose head has not arrived ``timeout_s`` after the connection opened or
after its first byte (408 if part of it came). Bodies and responses are uvicorn's as usual.

One approximation: the bytes of a head that starts inside the same read as the end of the
previous request are not counted, so a head may reach the limit plus one read.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Any

import httptools
from uvicorn.config import Config
from uvicorn.protocols.http.httptools_impl import STATUS_LINE, HttpToolsProtocol
from uvicorn.server import ServerState

from league.settings import Settings


@dataclass(frozen=True)
class HeadLimits:
    """What one request head (request line and header fields) may cost."""

    max_bytes: int
    max_count: int
    timeout_s: float

    @classmethod
    def of(cls, settings: Settings) -> HeadLimits:
        """The head limits of ``settings`` (``max_header_bytes`` and its neighbours)."""
        return cls(
            settings.max_header_bytes, settings.max_header_count, settings.header_timeout_seconds
        )


class HeadRefused(Exception):
    """Raised inside a parser callback to stop parsing a head over its limits."""


class BoundedHttpToolsProtocol(HttpToolsProtocol):
    """:class:`HttpToolsProtocol` that enforces :class:`HeadLimits` on every request head:
    ``config.head_limits`` (see :mod:`league.http.server_options`), else those of the
    environment's :class:`Settings`."""

    def __init__(
        self,
        config: Config,
        server_state: ServerState,
        app_state: dict[str, Any],
        _loop: asyncio.AbstractEventLoop | None = None,
    ) -> None:
        super().__init__(config, server_state, app_state, _loop)
        if getattr(config, "head_limits", None) is None:
            config.head_limits = HeadLimits.of(Settings())  # type: ignore[attr-defined]
        self.head_limits: HeadLimits = config.head_limits  # type: ignore[attr-defined]
        self._reading_head = True
        self._head_budget = self.head_limits.max_bytes
        self._head_fields = 0
        self._boundaries = 0  # heads and messages completed: where counting starts over
        self._head_timer: asyncio.TimerHandle | None = None

    # -------------------------------------------------------------------- connection
    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm_head_timer()

    def connection_lost(self, exc: Exception | None) -> None:
        self._cancel_head_timer()
        super().connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        while self._reading_head and len(data) > self._head_budget:
            done = self._boundaries
            budget = max(self._head_budget, 0)
            piece, data = data[:budget], data[budget:]
            self._feed(piece)
            if self.transport.is_closing():
                return
            if self._reading_head and self._boundaries == done:
                self._refuse(431, "Request header fields too large.")
                return
        if data:
            self._feed(data)

    def _feed(self, data: bytes) -> None:
        """uvicorn's ``data_received``, with 431 for a head refused inside the parser."""
        if self._reading_head and self._head_timer is None:
            self._arm_head_timer()
        self._unset_keepalive_if_required()
        done = self._boundaries
        try:
            self.parser.feed_data(data)
        except httptools.HttpParserCallbackError as exc:
            if isinstance(exc.__context__, HeadRefused):
                self._refuse(431, str(exc.__context__))
                return
            self.logger.warning("Invalid HTTP request received.")
            self.send_400_response("Invalid HTTP request received.")
            return
        except httptools.HttpParserError:
            self.logger.warning("Invalid HTTP request received.")
            self.send_400_response("Invalid HTTP request received.")
            return
        except httptools.HttpParserUpgrade:
            if self._should_upgrade():
                self.handle_websocket_upgrade()
            else:
                self._unsupported_upgrade_warning()
            return
        if self._reading_head and self._boundaries == done:  # all of it was head
            self._head_budget -= len(data)

    # ---------------------------------------------------------------- parser callbacks
    def on_header(self, name: bytes, value: bytes) -> None:
        self._head_fields += 1
        if self._head_fields > self.head_limits.max_count:
            raise HeadRefused("Too many request header fields.")
        super().on_header(name, value)

    def on_headers_complete(self) -> None:
        self._reading_head = False
        self._boundaries += 1
        self._cancel_head_timer()
        super().on_headers_complete()

    def on_message_complete(self) -> None:
        super().on_message_complete()
        self._boundaries += 1
        self._reading_head = True
        self._head_budget = self.head_limits.max_bytes
        self._head_fields = 0

    # -------------------------------------------------------------------------- timer
    def _arm_head_timer(self) -> None:
        self._cancel_head_timer()
        self._head_timer = self.loop.call_later(self.head_limits.timeout_s, self._head_timeout)

    def _cancel_head_timer(self) -> None:
        if self._head_timer is not None:
            self._head_timer.cancel()
            self._head_timer = None

    def _head_timeout(self) -> None:
        self._head_timer = None
        if not self._reading_head or self.transport.is_closing():
            return
        if self.cycle is not None and not self.cycle.response_complete:
            self._arm_head_timer()  # a pipelined head waits while the response is written
            return
        if self._head_budget < self.head_limits.max_bytes:
            self._refuse(408, "Request header timeout.")
        else:
            self.transport.close()  # an idle connection: nothing to answer

    def _refuse(self, status: int, message: str) -> None:
        """Answer ``status`` with ``message`` as plain text and close the connection."""
        self._cancel_head_timer()
        body = message.encode("ascii")
        content = [STATUS_LINE[status]]
        for name, value in self.server_state.default_headers:
            content.extend([name, b": ", value, b"\r\n"])
        content.extend(
            [
                b"content-type: text/plain; charset=utf-8\r\n",
                b"content-length: " + str(len(body)).encode("ascii") + b"\r\n",
                b"connection: close\r\n",
                b"\r\n",
                body,
            ]
        )
        self.transport.write(b"".join(content))
        self.transport.close()
