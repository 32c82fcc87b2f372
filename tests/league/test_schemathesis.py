"""Schemathesis over the live OpenAPI spec: no generated request may get a 5xx.

Every operation gets ``EXAMPLES`` generated cases as admin and as anonymous; the number of
cases run is printed (``-s``) and checked.
"""

from __future__ import annotations

import pytest
import schemathesis
from hypothesis import HealthCheck, Phase, given, settings

from tests.league.conftest import League
from tests.league.helpers import car, create_event, enter, record, upload

EXAMPLES = 15


def _fuzz(league: League, operation, headers: dict[str, str], failures: list[str]) -> int:
    """Run ``EXAMPLES`` generated cases of one operation; how many ran."""
    counted = 0

    @settings(
        max_examples=EXAMPLES,
        deadline=None,
        database=None,
        phases=[Phase.explicit, Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    @given(case=operation.as_strategy())
    def run(case) -> None:
        nonlocal counted
        counted += 1
        # A generous timeout: the suite shares the cores with trainers and browsers.
        response = case.call(base_url=league.url, headers=headers, timeout=60)
        if response.status_code >= 500:
            failures.append(f"{case.method} {case.formatted_path}: {response.text[:200]}")

    run()
    return counted


@pytest.mark.slow
def test_no_server_errors(league: League) -> None:
    event = create_event(league, name="Fuzz")
    model = upload(league, "admin", seed=301)
    entry = enter(league, "admin", event["id"], model["id"])
    record(league, event["id"], {entry["entry_id"]: car("fuzz")})
    schema = schemathesis.openapi.from_url(f"{league.url}/openapi.json")
    operations = [result.ok() for result in schema.get_all_operations()]
    # Rotating the admin's token would turn every later operation into a 401: it goes last.
    operations.sort(key=lambda op: op.path == "/api/racers/me/token")
    failures: list[str] = []
    counted = 0
    for operation in operations:
        for who in ("admin", None):
            headers = {"Authorization": f"Bearer {league.tokens[who]}"} if who else {}
            counted += _fuzz(league, operation, headers, failures)
    print(f"schemathesis: {counted} cases over {len(operations)} operations, {league.backend}")
    assert counted >= len(operations) * 2 * 5
    assert failures == []
