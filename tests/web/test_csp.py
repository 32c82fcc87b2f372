"""The pages and the API docs work under the server's Content-Security-Policy in Chromium.

Violations are caught two ways: the console messages Chromium writes for them, and the
``securitypolicyviolation`` events, recorded by an init script (which runs outside the
page's CSP).
"""

from __future__ import annotations

from tests.league.conftest import League
from tests.web.data import Site
from tests.web.test_browser import sign_in

RECORD_VIOLATIONS = """
window.__cspViolations = [];
document.addEventListener("securitypolicyviolation", (e) => {
  window.__cspViolations.push(e.violatedDirective + " " + (e.blockedURI || "inline"));
});
"""


def watch_csp(page) -> list[str]:
    """Record CSP violations of every page ``page`` loads; the list grows as they happen."""
    messages: list[str] = []
    page.on(
        "console",
        lambda m: messages.append(m.text) if "Content Security Policy" in m.text else None,
    )
    page.add_init_script(RECORD_VIOLATIONS)
    return messages


def violations(page, console: list[str]) -> list[str]:
    return console + page.evaluate("() => window.__cspViolations")


def test_docs_render_the_api_under_the_csp(page, league: League) -> None:
    console = watch_csp(page)
    sign_in(page, league, "alice")
    page.goto("/docs")
    page.wait_for_selector("#token-who:has-text('signed in as alice')")  # common.js ran
    routes = page.eval_on_selector_all(".api-op h2 code", "cs => cs.map(c => c.textContent)")
    assert "POST /api/models" in routes and "GET /api/events/{event_id}/leaderboard" in routes
    page.wait_for_load_state("networkidle")
    assert violations(page, console) == []


def test_pages_work_without_csp_violations(page, league: League, site: Site) -> None:
    console = watch_csp(page)
    sign_in(page, league, "alice")
    checks = {
        "/": ".thumb svg",
        f"/events/{site.head_to_head}": "#leaderboard tbody tr[data-model-id] .ubar .range",
        f"/races/{site.races['h2h1']}": ".swatch",
        f"/models/{site.models['alice']}": "main h1",
        "/upload": "form",
        "/garage": "main[data-loaded=true]",
        "/garage/new": ".CodeMirror",
        "/garage/bench": ".CodeMirror",
    }
    for path, selector in checks.items():
        page.goto(path)
        page.wait_for_selector(selector)
        page.wait_for_load_state("networkidle")
        assert violations(page, console) == [], path


def test_the_watch_sees_an_inline_script(page) -> None:
    """The check above would notice: an injected inline script is refused and recorded."""
    console = watch_csp(page)
    page.goto("/")
    page.evaluate(
        "() => { const s = document.createElement('script');"
        " s.textContent = 'window.ran = true'; document.body.append(s); }"
    )
    page.wait_for_function("() => window.__cspViolations.length > 0")
    assert page.evaluate("() => window.ran === undefined")
    assert any("script-src" in v for v in violations(page, console))
