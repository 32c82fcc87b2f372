"""Refuse request bodies over a size cap (413) before they are parsed or spooled to disk.

``Content-Length`` is checked up front; a body sent without one (chunked) is counted as it
arrives and cut off at the cap.
"""

from __future__ import annotations

import json
from typing import Any

Scope = dict[str, Any]


class BodyTooLarge(BaseException):  # not Exception: frameworks must not swallow it
    """Raised inside the app's ``receive`` once the body passes the cap."""


class BodyLimitMiddleware:
    """An ASGI middleware capping every request body at ``max_bytes``."""

    def __init__(self, app: Any, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    def _message(self) -> str:
        return f"The request body is larger than the server's limit of {self.max_bytes} bytes."

    async def _refuse(self, send: Any) -> None:
        body = json.dumps({"detail": self._message()}).encode()
        headers = [(b"content-type", b"application/json"), (b"connection", b"close")]
        headers.append((b"content-length", str(len(body)).encode()))
        await send({"type": "http.response.start", "status": 413, "headers": headers})
        await send({"type": "http.response.body", "body": body})

    async def __call__(self, scope: Scope, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        for name, value in scope.get("headers", ()):
            too_big = not value.isdigit() or int(value) > self.max_bytes
            if name == b"content-length" and too_big:
                await self._refuse(send)
                return
        seen = 0
        started = False

        async def counted_receive() -> Any:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.max_bytes:
                    raise BodyTooLarge
            return message

        async def tracked_send(message: Any) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, counted_receive, tracked_send)
        except BodyTooLarge:
            if not started:
                await self._refuse(send)
