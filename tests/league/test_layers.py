"""Only the code that serves HTTP imports the web framework: workers and the scheduler
never load FastAPI or Starlette."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import league

LEAGUE = Path(league.__file__).parent
WEB_FRAMEWORKS = ("fastapi", "starlette")
HTTP_PACKAGES = ("http", "web")
"""The subpackages of ``league`` that serve HTTP, the only ones that may import them."""
NOT_HTTP = (
    "league.cli",
    "league.crud",
    "league.demo",
    "league.ranking",
    "league.tokens",
    "league.jobs.scheduler",
    "league.jobs.worker",
    "league.store",
    "league.store.s3",
    "league.store.sweep",
    "league.http.upload_validation",  # the validation child, under a memory limit
    "league.training.queue",
    "league.training.trainer",
)


def _imported(path: Path) -> set[str]:
    """The top-level package of every module that ``path`` imports."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found |= {alias.name.partition(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module.partition(".")[0])
    return found


def test_only_the_http_packages_import_the_web_framework() -> None:
    offenders = [
        str(path.relative_to(LEAGUE.parent))
        for path in sorted(LEAGUE.rglob("*.py"))
        if path.relative_to(LEAGUE).parts[0] not in HTTP_PACKAGES
        and _imported(path) & set(WEB_FRAMEWORKS)
    ]
    assert offenders == []


def test_workers_and_the_scheduler_never_load_the_web_framework() -> None:
    """Imported in a fresh interpreter, none of these pulls FastAPI in, even indirectly."""
    probe = (
        "import importlib, json, sys\n"
        "names, frameworks = json.loads(sys.argv[1])\n"
        "for name in names:\n"
        "    importlib.import_module(name)\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.partition('.')[0] in frameworks)))\n"
    )
    given = json.dumps([NOT_HTTP, WEB_FRAMEWORKS])
    command = [sys.executable, "-c", probe, given]
    out = subprocess.run(command, capture_output=True, text=True, check=True, timeout=120).stdout
    assert json.loads(out.splitlines()[-1]) == []
