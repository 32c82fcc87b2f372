"""``LeagueClient``: a small httpx client for the league API (used by the CLI)."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx

STREAM_RETRIES = 5
"""Reconnections in a row :meth:`LeagueClient.training_events` tries after a broken stream."""


class LeagueError(RuntimeError):
    """The server refused a request; ``status`` and the server's message are kept."""

    def __init__(
        self,
        status: int,
        message: str,
        problems: list[dict] | None = None,
        retry_after: int | None = None,
    ) -> None:
        super().__init__(f"{status}: {message}")
        self.status = status
        self.message = message
        self.problems = problems or []
        self.retry_after = retry_after  # seconds, from a 429's or 503's Retry-After


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
        return self._request(method, url, **kwargs).json()

    def _request(self, method: str, url: str, **kwargs: Any) -> httpx.Response:
        response = self._http.request(method, url, **kwargs)
        _raise_for_refusal(response)
        return response

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

    # Training jobs (/api/training-jobs).

    def create_training_job(self, body: dict[str, Any]) -> dict[str, Any]:
        """Queue a training job (``TrainingJobCreate``'s fields); the job as created."""
        return self._call("POST", "/api/training-jobs", json=body)

    def training_jobs(self, status: str | None = None) -> list[dict[str, Any]]:
        """Your training jobs, newest first (only those in ``status`` when given)."""
        params = {"status": status} if status else {}
        return self._call("GET", "/api/training-jobs", params=params)

    def training_quota(self) -> dict[str, Any]:
        """Your training minutes this month: ``minutes_used``, ``minutes_per_month``,
        ``resets_at``."""
        return self._call("GET", "/api/training-jobs/quota")

    def training_job(self, job_id: int) -> dict[str, Any]:
        """One of your training jobs."""
        return self._call("GET", f"/api/training-jobs/{job_id}")

    def stop_training_job(self, job_id: int) -> dict[str, Any]:
        """Stop a training job (a queued one at once, a running one within a heartbeat)."""
        return self._call("POST", f"/api/training-jobs/{job_id}/stop")

    def training_metrics(self, job_id: int, after: int = 0) -> list[dict[str, Any]]:
        """The job's iterations after the event id ``after``, each with its event ``id``."""
        return self._call("GET", f"/api/training-jobs/{job_id}/metrics", params={"after": after})

    def training_logs(self, job_id: int, after: int = 0) -> str:
        """The job's log lines (and status changes) after the event id ``after``, as text."""
        url = f"/api/training-jobs/{job_id}/logs"
        return self._request("GET", url, params={"after": after}).text

    def training_events(self, job_id: int, last_event_id: int = 0) -> Iterator[tuple[str, dict]]:
        """The job's events live, as ``(event, data)`` pairs (``event``: iteration, log or
        status) after the event id ``last_event_id``, until the server ends the stream (once
        the job has ended). The stream has no read timeout; a stream broken mid-way is
        resumed from the last event received (up to ``STREAM_RETRIES`` times in a row)."""
        url = f"/api/training-jobs/{job_id}/events"
        timeout = self._http.timeout.as_dict() | {"read": None}
        failures, connected = 0, False
        while True:
            headers = {"Last-Event-ID": str(last_event_id), "Accept": "text/event-stream"}
            try:
                with self._http.stream(
                    "GET", url, headers=headers, timeout=httpx.Timeout(**timeout)
                ) as response:
                    if response.status_code >= 400:
                        response.read()
                        _raise_for_refusal(response)
                    connected = True
                    for event_id, event, data in _server_sent_events(response.iter_lines()):
                        failures = 0
                        last_event_id = event_id if event_id is not None else last_event_id
                        yield event, data
                return
            except httpx.TransportError:
                failures += 1
                if not connected or failures > STREAM_RETRIES:
                    raise
                time.sleep(min(2.0**failures, 30.0))

    def download_run(self, job_id: int, path: str | Path) -> Path:
        """Save the job's run folder (a zip) to ``path``; the path."""
        path = Path(path)
        with self._http.stream("GET", f"/api/training-jobs/{job_id}/run.zip") as response:
            if response.status_code >= 400:
                response.read()
                _raise_for_refusal(response)
            partial = path.with_name(path.name + ".part")
            with partial.open("wb") as handle:
                for chunk in response.iter_bytes():
                    handle.write(chunk)
            partial.replace(path)
        return path


def _raise_for_refusal(response: httpx.Response) -> None:
    """Raise :class:`LeagueError` for an error answer (its ``detail``, ``problems`` and
    ``Retry-After``)."""
    if response.status_code < 400:
        return
    try:
        body = response.json()
    except ValueError:
        body = None
    if not isinstance(body, dict):
        body = {"detail": response.text[:500]}
    retry = response.headers.get("Retry-After", "")
    retry_after = int(retry) if retry.isdigit() else None
    raise LeagueError(
        response.status_code, str(body.get("detail")), body.get("problems"), retry_after
    )


def _server_sent_events(lines: Iterator[str]) -> Iterator[tuple[int | None, str, dict]]:
    """Parse a Server-Sent Events stream into ``(id, event, data)``: ``data`` read as JSON
    (a non-JSON payload as ``{"text": ...}``); comments and empty events are skipped."""
    event_id: int | None = None
    event, data = "", []
    for line in lines:
        if not line:
            if data:
                payload = "\n".join(data)
                try:
                    parsed = json.loads(payload)
                except ValueError:
                    parsed = {"text": payload}
                if not isinstance(parsed, dict):
                    parsed = {"value": parsed}
                yield event_id, event or "message", parsed
            event, data = "", []
            continue
        if line.startswith(":"):
            continue
        field, _, value = line.partition(":")
        value = value.removeprefix(" ")
        if field == "data":
            data.append(value)
        elif field == "event":
            event = value
        elif field == "id" and value.isdigit():
            event_id = int(value)
