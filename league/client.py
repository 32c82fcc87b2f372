"""``LeagueClient``: a small httpx client for the league API (used by the CLI)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx


class LeagueError(RuntimeError):
    """The server refused a request; ``status`` and the server's message are kept."""

    def __init__(self, status: int, message: str, problems: list[dict] | None = None) -> None:
        super().__init__(f"{status}: {message}")
        self.status = status
        self.message = message
        self.problems = problems or []


class LeagueClient:
    """Calls to one league server, authenticated with a bearer token when one is given."""

    def __init__(self, server: str, token: str | None = None, timeout: float = 60.0) -> None:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self._http = httpx.Client(base_url=server.rstrip("/"), headers=headers, timeout=timeout)

    def close(self) -> None:
        """Close the connection pool."""
        self._http.close()

    def __enter__(self) -> LeagueClient:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def _call(self, method: str, url: str, **kwargs: Any) -> Any:
        response = self._http.request(method, url, **kwargs)
        if response.status_code >= 400:
            try:
                body = response.json()
            except ValueError:
                body = {"detail": response.text[:500]}
            raise LeagueError(response.status_code, str(body.get("detail")), body.get("problems"))
        return response.json()

    def me(self) -> dict[str, Any]:
        """The racer the token belongs to."""
        return self._call("GET", "/api/racers/me")

    def upload_model(self, path: str | Path, name: str | None = None) -> dict[str, Any]:
        """Upload a model archive; the server's model record."""
        path = Path(path)
        data = {"name": name} if name else {}
        with path.open("rb") as handle:
            files = {"file": (path.name, handle, "application/zip")}
            return self._call("POST", "/api/models", files=files, data=data)

    def enter(self, event_id: int, model_id: int) -> dict[str, Any]:
        """Enter a model in an event; the entry and its job ids."""
        return self._call("POST", f"/api/events/{event_id}/entries", json={"model_id": model_id})

    def event(self, event_id: int) -> dict[str, Any]:
        """One event."""
        return self._call("GET", f"/api/events/{event_id}")

    def leaderboard(self, event_id: int) -> dict[str, Any]:
        """An event's standings."""
        return self._call("GET", f"/api/events/{event_id}/leaderboard")

    def job(self, job_id: int) -> dict[str, Any]:
        """One job's state."""
        return self._call("GET", f"/api/jobs/{job_id}")
