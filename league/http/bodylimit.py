"""Cap request bodies per route (413) and give them a deadline to arrive (408).

Both are decided here, outside the app, so a refused body is never parsed, spooled to disk
or looked at by the auth dependencies. Every route gets the default :class:`BodyRule`
(small: JSON bodies) unless it is named in ``routes`` (the model upload).

``Content-Length`` is checked up front; a body sent without one (chunked) is counted as it
arrives and cut off at the cap. The deadline runs from the moment the request's headers
are in until its last body byte: a body that trickles in slower gets 408.
"""

from __future__ import annotations

import asyncio
import json
from dataclasses import dataclass
from typing import Any

Scope = dict[str, Any]


@dataclass(frozen=True)
class BodyRule:
    """How large a request body may be and how long it may take to arrive."""

    max_bytes: int
    timeout_s: float


class BodyRefused(BaseException):  # not Exception: frameworks must not swallow it
    """Raised inside the app's ``receive`` when the body breaks its rule."""

    def __init__(self, status: int, detail: str) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail


def too_large(rule: BodyRule) -> BodyRefused:
    """The 413 refusal of ``rule``."""
    detail = f"The request body is larger than this route's limit of {rule.max_bytes} bytes."
    return BodyRefused(413, detail)


def too_slow(rule: BodyRule) -> BodyRefused:
    """The 408 refusal of ``rule``."""
    detail = f"The request body did not arrive within {rule.timeout_s:g} s."
    return BodyRefused(408, detail)


async def send_refusal(send: Any, refusal: BodyRefused) -> None:
    """Answer ``refusal`` as JSON and close the connection (the rest of the body is unread)."""
    body = json.dumps({"detail": refusal.detail}).encode()
    headers = [(b"content-type", b"application/json"), (b"connection", b"close")]
    headers.append((b"content-length", str(len(body)).encode()))
    await send({"type": "http.response.start", "status": refusal.status, "headers": headers})
    await send({"type": "http.response.body", "body": body})


def declared_length(scope: Scope) -> int | None:
    """The request's ``Content-Length``; -1 when it is not a number, None when absent."""
    for name, value in scope.get("headers", ()):
        if name == b"content-length":
            return int(value) if value.isdigit() else -1
    return None


class BodyLimitMiddleware:
    """An ASGI middleware holding every request body to its route's :class:`BodyRule`."""

    def __init__(
        self, app: Any, default: BodyRule, routes: dict[tuple[str, str], BodyRule] | None = None
    ) -> None:
        self.app = app
        self.default = default
        self.routes = routes or {}

    def rule_for(self, scope: Scope) -> BodyRule:
        """The rule of the request's ``(method, path)``, else the default."""
        return self.routes.get((scope["method"], scope["path"]), self.default)

    async def __call__(self, scope: Scope, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        rule = self.rule_for(scope)
        length = declared_length(scope)
        if length is not None and not 0 <= length <= rule.max_bytes:
            await send_refusal(send, too_large(rule))
            return
        deadline = asyncio.get_running_loop().time() + rule.timeout_s
        seen = 0
        body_done = False
        started = False

        async def limited_receive() -> Any:
            nonlocal seen, body_done
            if body_done:  # later calls only wait for a disconnect: no deadline
                return await receive()
            try:
                async with asyncio.timeout_at(deadline):
                    message = await receive()
            except TimeoutError:
                raise too_slow(rule) from None
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > rule.max_bytes:
                    raise too_large(rule)
                body_done = not message.get("more_body", False)
            return message

        async def tracked_send(message: Any) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, limited_receive, tracked_send)
        except BodyRefused as refusal:
            if not started:
                await send_refusal(send, refusal)
