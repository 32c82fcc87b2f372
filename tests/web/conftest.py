"""Web test fixtures: one league server with real races for the whole package, and a
headless Chromium (Debian's ``/usr/bin/chromium`` driven by Playwright).

Browser tests skip with a message when Chromium or Playwright is missing, and fail instead
under ``CI=true`` (see ``tests.prerequisites``); the page tests that need no browser always
run.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest

from league.settings import MiB
from tests.league.conftest import Database, League, start_league
from tests.prerequisites import skip_or_fail
from tests.web.data import Site, populate

CHROMIUM = os.environ.get("SLIPSTREAM_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
SCREENSHOTS_ENV = "SLIPSTREAM_WEB_SCREENSHOTS"


@pytest.fixture(scope="package")
def league(tmp_path_factory: pytest.TempPathFactory) -> Iterator[League]:
    """A running league on a fresh SQLite database, whose uploads may be as large as a
    trained camera model (the garage makes models of a run's checkpoints)."""
    folder = tmp_path_factory.mktemp("web")
    database = Database(f"sqlite:///{folder / 'league.db'}", "sqlite")
    yield from start_league(database, folder / "data", max_upload_bytes=8 * MiB)


@pytest.fixture(scope="package")
def site(league: League) -> Site:
    """The league filled with events and real races (see ``tests.web.data``)."""
    return populate(league)


@pytest.fixture(scope="package")
def browser() -> Iterator[object]:
    """Headless Chromium, or a skip (a failure under ``CI=true``) that says what is missing."""
    if not Path(CHROMIUM).exists() and shutil.which("chromium") is None:
        skip_or_fail(f"browser tests: Chromium not found at {CHROMIUM} (apt-get install chromium)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        skip_or_fail("browser tests: the 'playwright' Python package is not installed")
    executable = CHROMIUM if Path(CHROMIUM).exists() else shutil.which("chromium")
    with sync_playwright() as playwright:
        chromium = playwright.chromium.launch(executable_path=executable, args=CHROMIUM_ARGS)
        yield chromium
        chromium.close()


@pytest.fixture
def page(browser, league: League) -> Iterator[object]:
    """A fresh browser page (own storage) with a desktop-sized viewport."""
    context = browser.new_context(viewport={"width": 1440, "height": 900}, base_url=league.url)
    context.set_default_timeout(15_000)
    tab = context.new_page()
    yield tab
    context.close()


@pytest.fixture
def screenshot_dir() -> Path | None:
    """Where to save screenshots for the docs (``$SLIPSTREAM_WEB_SCREENSHOTS``), if anywhere."""
    folder = os.environ.get(SCREENSHOTS_ENV)
    return Path(folder) if folder else None
