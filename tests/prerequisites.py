"""What some tests need from the machine (Chromium, PostgreSQL), and what happens without it.

Locally a missing prerequisite skips the test with a message. Under ``CI=true`` (``.ci/run``
sets it) it fails the test instead, so CI cannot go green with those checks skipped. Real
DeepRacer data (``../shared/deepracer-data``) is not a prerequisite of this kind: tests
that read it skip when it is absent, in CI too.
"""

from __future__ import annotations

import os
from typing import NoReturn

import pytest

POSTGRES_ENV = "SLIPSTREAM_TEST_POSTGRES_URL"


def in_ci() -> bool:
    """Whether the tests run in CI (``CI=true``), where nothing may be skipped for lack of it."""
    return os.environ.get("CI") == "true"


def skip_or_fail(reason: str) -> NoReturn:
    """Skip the test with ``reason``; under ``CI=true`` fail it with the same reason."""
    if in_ci():
        pytest.fail(f"{reason} (with CI=true this is a failure, not a skip)", pytrace=False)
    pytest.skip(reason)


def postgres_url() -> str:
    """The PostgreSQL server URL for tests (``$SLIPSTREAM_TEST_POSTGRES_URL``), or skip/fail."""
    url = os.environ.get(POSTGRES_ENV)
    if not url:
        skip_or_fail(f"PostgreSQL variant: {POSTGRES_ENV} is not set")
    return url
