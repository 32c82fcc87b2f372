"""Per-client request rate limiting: a token bucket per racer, else per client address.

A request is charged to its racer's bucket only once its token has checked out: the auth
dependency records ``racer_id`` in the request state, and the middleware remembers that
token (as a digest) for later requests. Any other request, anonymous or with a token the
server has not seen succeed, is charged to its client address, so a flood of random
tokens from one address shares one bucket. A token that later answers 401 (revoked,
rotated) is forgotten.

IPv6 clients are keyed by their /64 (one subscriber's usual allocation), IPv4 clients by
address. Both tables are bounded: past ``max_keys`` the least recently used key is evicted,
so a flood of new keys never resets the buckets of clients that keep coming.

A pure ASGI middleware, so it costs a few dict lookups per request. Buckets live in memory:
with several server processes each enforces the limit on its own share of the traffic.
"""

from __future__ import annotations

import hashlib
import ipaddress
import json
import math
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

Scope = dict[str, Any]
ASGIApp = Callable[..., Any]
EXEMPT_PATHS = ("/healthz", "/readyz")
MAX_KEYS = 100_000
IPV6_PREFIX = 64


class TokenBucket:
    """``rate`` tokens per second up to ``burst``; ``take(key)`` answers wait seconds or 0.

    At most ``max_keys`` buckets are kept; a new key past that evicts the least recently
    used one (a bucket idle that long has mostly refilled, so little is forgiven).
    """

    def __init__(self, rate: float, burst: int, max_keys: int = MAX_KEYS) -> None:
        self.rate = rate
        self.burst = float(burst)
        self.max_keys = max_keys
        self._buckets: OrderedDict[str, tuple[float, float]] = OrderedDict()
        self._lock = threading.Lock()

    def take(self, key: str, now: float | None = None) -> float:
        """Spend one token for ``key``: 0.0 if allowed, else seconds until one is free."""
        now = time.monotonic() if now is None else now
        with self._lock:
            tokens, last = self._buckets.get(key, (self.burst, now))
            tokens = min(self.burst, tokens + (now - last) * self.rate)
            wait = 0.0 if tokens >= 1.0 else (1.0 - tokens) / self.rate
            self._buckets[key] = (tokens if wait else tokens - 1.0, now)
            self._buckets.move_to_end(key)
            while len(self._buckets) > self.max_keys:
                self._buckets.popitem(last=False)
            return wait

    def __len__(self) -> int:
        """How many keys have a bucket now."""
        return len(self._buckets)


class KnownTokens:
    """Digests of bearer tokens that checked out, mapped to their racer id (bounded, LRU)."""

    def __init__(self, max_keys: int = MAX_KEYS) -> None:
        self.max_keys = max_keys
        self._racers: OrderedDict[str, int] = OrderedDict()
        self._lock = threading.Lock()

    def racer(self, digest: str) -> int | None:
        """The racer whose token has this digest, if it was seen to check out."""
        with self._lock:
            racer_id = self._racers.get(digest)
            if racer_id is not None:
                self._racers.move_to_end(digest)
            return racer_id

    def remember(self, digest: str, racer_id: int) -> None:
        """Record a token that checked out, evicting the least recently used past the cap."""
        with self._lock:
            self._racers[digest] = racer_id
            self._racers.move_to_end(digest)
            while len(self._racers) > self.max_keys:
                self._racers.popitem(last=False)

    def forget(self, digest: str) -> None:
        """Drop a token that no longer checks out."""
        with self._lock:
            self._racers.pop(digest, None)


def token_digest(scope: Scope) -> str | None:
    """A digest of the request's ``Authorization`` header, or None without one."""
    for name, value in scope.get("headers", ()):
        if name == b"authorization":
            return hashlib.sha256(value).hexdigest()
    return None


def address_key(scope: Scope) -> str:
    """The bucket of the client address: the address for IPv4, its /64 for IPv6."""
    client = scope.get("client")
    host = client[0] if client else "unknown"
    try:
        address = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:
        return "ip:" + host[:64]
    if isinstance(address, ipaddress.IPv6Address):
        if address.ipv4_mapped is not None:
            return f"ip:{address.ipv4_mapped}"
        return f"ip:{ipaddress.IPv6Network((address, IPV6_PREFIX), strict=False)}"
    return f"ip:{address}"


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
