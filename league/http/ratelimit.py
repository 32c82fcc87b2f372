"""Per-client request rate limiting: a token bucket per racer, else per client address.

A request is charged to its racer's bucket only once its token has checked out: the auth
dependency records ``racer_id`` in the request state, and the middleware remembers that
token (as a digest) for later requests. Any other request, anonymous or with a token the
server has not seen succeed, is charged to its client address, so a flood of random
tokens from one address shares one bucket. A token that later answers 401 (revoked,
rotated) is forgotten.

A pure ASGI middleware, so it costs a few dict lookups per request. Buckets live in memory:
with several server processes each enforces the limit on its own share of the traffic.
"""

from __future__ import annotations

import hashlib
import json
import math
import threading
import time
from collections.abc import Callable
from typing import Any

Scope = dict[str, Any]
ASGIApp = Callable[..., Any]
EXEMPT_PATHS = ("/healthz", "/readyz")


class TokenBucket:
    """``rate`` tokens per second up to ``burst``; ``take(key)`` answers wait seconds or 0."""

    def __init__(self, rate: float, burst: int, max_keys: int = 100_000) -> None:
        self.rate = rate
        self.burst = float(burst)
        self.max_keys = max_keys
        self._buckets: dict[str, tuple[float, float]] = {}
        self._lock = threading.Lock()

    def take(self, key: str, now: float | None = None) -> float:
        """Spend one token for ``key``: 0.0 if allowed, else seconds until one is free."""
        now = time.monotonic() if now is None else now
        with self._lock:
            tokens, last = self._buckets.get(key, (self.burst, now))
            tokens = min(self.burst, tokens + (now - last) * self.rate)
            if tokens < 1.0:
                self._buckets[key] = (tokens, now)
                return (1.0 - tokens) / self.rate
            if len(self._buckets) >= self.max_keys and key not in self._buckets:
                self._buckets.clear()  # a flood of new keys: start over rather than grow
            self._buckets[key] = (tokens - 1.0, now)
            return 0.0


class KnownTokens:
    """Digests of bearer tokens that checked out, mapped to their racer id (bounded)."""

    def __init__(self, max_keys: int = 100_000) -> None:
        self.max_keys = max_keys
        self._racers: dict[str, int] = {}

    def racer(self, digest: str) -> int | None:
        """The racer whose token has this digest, if it was seen to check out."""
        return self._racers.get(digest)

    def remember(self, digest: str, racer_id: int) -> None:
        """Record a token that checked out."""
        if len(self._racers) >= self.max_keys and digest not in self._racers:
            self._racers.clear()
        self._racers[digest] = racer_id

    def forget(self, digest: str) -> None:
        """Drop a token that no longer checks out."""
        self._racers.pop(digest, None)


def token_digest(scope: Scope) -> str | None:
    """A digest of the request's ``Authorization`` header, or None without one."""
    for name, value in scope.get("headers", ()):
        if name == b"authorization":
            return hashlib.sha256(value).hexdigest()
    return None


def address_key(scope: Scope) -> str:
    """The bucket of the client address."""
    client = scope.get("client")
    return "ip:" + (client[0] if client else "unknown")


class RateLimitMiddleware:
    """Answer 429 (with ``Retry-After``) to clients over their rate."""

    def __init__(self, app: ASGIApp, rate: float, burst: int) -> None:
        self.app = app
        self.bucket = TokenBucket(rate, burst) if rate > 0 else None
        self.known = KnownTokens()

    def client_key(self, scope: Scope, digest: str | None) -> str:
        """The bucket: the racer once their token checked out, else the client address."""
        racer_id = self.known.racer(digest) if digest else None
        return f"racer:{racer_id}" if racer_id is not None else address_key(scope)

    async def __call__(self, scope: Scope, receive: Any, send: Any) -> None:
        if self.bucket is None or scope["type"] != "http" or scope["path"] in EXEMPT_PATHS:
            await self.app(scope, receive, send)
            return
        digest = token_digest(scope)
        wait = self.bucket.take(self.client_key(scope, digest))
        if wait > 0.0:
            await self._refuse(send, wait)
            return
        if digest is None:
            await self.app(scope, receive, send)
            return
        state = scope.setdefault("state", {})  # request.state of the app, where auth writes

        async def learning_send(message: Any) -> None:
            if message["type"] == "http.response.start":
                if message["status"] == 401:
                    self.known.forget(digest)
                elif isinstance(state.get("racer_id"), int):
                    self.known.remember(digest, state["racer_id"])
            await send(message)

        await self.app(scope, receive, learning_send)

    async def _refuse(self, send: Any, wait: float) -> None:
        retry = str(max(1, math.ceil(wait)))
        body = json.dumps(
            {"detail": f"Too many requests: slow down and retry in {retry} s."}
        ).encode()
        await send(
            {
                "type": "http.response.start",
                "status": 429,
                "headers": [
                    (b"content-type", b"application/json"),
                    (b"content-length", str(len(body)).encode()),
                    (b"retry-after", retry.encode()),
                ],
            }
        )
        await send({"type": "http.response.body", "body": body})
