"""Hostile uploads against a real server: refused in a child, under its limits, a few at once.

The server runs in this process (a thread), so this process's memory is the API process's:
a file that made the API build its onnxruntime session would show in ``VmHWM`` here. How
fast the refusals and ``/healthz`` answer is measured by ``benchmarks/hostile_uploads.py``.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import pytest

from league import crud
from league.http.upload_validation import UploadValidator
from league.models import Racer
from league.settings import Settings
from league.store.local import LocalFileStore
from submissions import ValidationReport, validate
from tests.league.conftest import Database, League, start_league
from tests.league.helpers import model_rows
from tests.submissions.hostile_models import broadcast_bomb, matmul_chain, wide_mlp

MiB = 1024 * 1024
# Only a bound on a hung server: /healthz answers in milliseconds.
HANG_GUARD_S = 30.0


@pytest.fixture(scope="module")
def league(database: Database, tmp_path_factory: pytest.TempPathFactory) -> Iterator[League]:
    """Two validations at once, one upload waiting (uploads up to 256 KiB)."""
    yield from start_league(
        database,
        tmp_path_factory.mktemp("hardening") / "data",
        validation_concurrency=2,
        validation_queue=1,
    )


def _peak_rss() -> int:
    """This process's peak resident memory (bytes), from ``/proc``."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmHWM")


def _post(league: League, data: bytes, who: str = "alice") -> httpx.Response:
    with league.client(who) as client:
        return client.post("/api/models", files={"file": ("m.zip", data)})


def _at_once(league: League, files: list[bytes]) -> list[httpx.Response]:
    """Upload every file from its own thread, all released at the same moment."""
    gate = threading.Barrier(len(files))

    def send(data: bytes) -> httpx.Response:
        gate.wait()
        return _post(league, data)

    with ThreadPoolExecutor(len(files)) as pool:
        return list(pool.map(send, files))


def _refused(league: League, data: bytes) -> list[dict]:
    """Upload ``data``; assert a 422 that left no row, keeping the API's memory flat."""
    rows, peak = model_rows(league), _peak_rss()
    response = _post(league, data)
    assert response.status_code == 422, response.text
    assert _peak_rss() - peak < 200 * MiB
    assert model_rows(league) == rows
    return response.json()["problems"]


def test_broadcast_bomb_is_refused_by_the_static_check(league: League) -> None:
    (problem,) = _refused(league, broadcast_bomb(16384))
    assert problem["field"] == "policy.onnx:graph" and "race's memory" in problem["message"]
    assert "(16384, 16384)" in problem["found"]


def test_hidden_bomb_hits_the_childs_memory_limit(league: League) -> None:
    (problem,) = _refused(league, broadcast_bomb(16384, hidden=True))
    assert problem["message"] == "The policy needs more memory than a race allows."
    assert f"{league.settings.race_memory_mb} MiB" in problem["expected"]


def test_matmul_chain_is_refused_by_the_static_check(league: League) -> None:
    (problem,) = _refused(league, matmul_chain(1500, size=128))
    assert problem["field"] == "policy.onnx:graph" and "too much arithmetic" in problem["message"]


def test_hidden_matmul_chain_hits_the_childs_cpu_limit(tmp_path: Path) -> None:
    """Stopped by its 2 s of CPU, not by the wall limit (a different message), which is set
    far enough off for a busy machine: only a hang guard."""
    settings = Settings(
        data_dir=tmp_path,
        max_upload_bytes=32 * MiB,
        validation_cpu_seconds=2,
        validation_wall_seconds=60.0,
    )
    validator = UploadValidator(settings)

    async def judge(data: bytes) -> ValidationReport:
        async with validator.slot():
            return await validator.validate(data)

    report = asyncio.run(judge(matmul_chain(200, hidden=True)))
    (problem,) = report.problems
    assert "too much CPU" in problem.message and "2 s of CPU time" in problem.expected


def _validation_children() -> list[int]:
    found = []
    for task in Path("/proc/self/task").glob("*/children"):
        for pid in task.read_text().split():
            cmdline = Path(f"/proc/{pid}/cmdline")
            if cmdline.exists() and b"league.http.upload_validation" in cmdline.read_bytes():
                found.append(int(pid))
    return found


def test_one_racers_flood_gets_429_past_their_share_and_healthz_answers(league: League) -> None:
    """Eight uploads of one racer at once: their share of the validation slots (two) is
    validated, the rest refused at once with 429 (never 503: the other racers' slots stay
    free), and ``/healthz`` answers throughout."""
    files = [wide_mlp(128, seed=300 + i) for i in range(8)]
    statuses: list[int] = []  # every /healthz answer (0: none)
    midflood, stop = [0], threading.Event()  # 200s asked and answered while children ran

    def probe() -> None:
        with httpx.Client(base_url=league.url, timeout=HANG_GUARD_S) as client:
            while not stop.is_set():
                validating = bool(_validation_children())
                try:
                    status = client.get("/healthz").status_code
                except httpx.HTTPError:
                    status = 0
                statuses.append(status)
                midflood[0] += validating and status == 200 and not stop.is_set()
                time.sleep(0.02)

    prober = threading.Thread(target=probe)
    prober.start()
    answers = _at_once(league, files)
    stop.set()
    prober.join()
    codes = sorted(r.status_code for r in answers)
    assert set(codes) == {201, 429} and codes.count(201) >= 2, codes
    refused = [r for r in answers if r.status_code == 429]
    assert all(
        r.headers["Retry-After"].isdigit() and "the most one racer may have" in r.text
        for r in refused
    )
    assert set(statuses) == {200} and midflood[0] >= 1, (statuses, midflood)
    assert _validation_children() == []


def test_same_file_twice_at_once_gives_one_model(league: League) -> None:
    for seed in range(400, 404):
        data = wide_mlp(64, seed=seed)
        answers = _at_once(league, [data, data])
        assert sorted(r.status_code for r in answers) == [200, 201], [r.text for r in answers]
        assert answers[0].json()["id"] == answers[1].json()["id"]


class RivalCommitsFirst(LocalFileStore):
    """A local store whose ``put`` lets a rival request store the same upload before returning:
    the moment two identical uploads race between the duplicate check and the commit."""

    def __init__(self, league: League, rival_info: object) -> None:
        super().__init__(league.settings.storage_dir)
        self.league, self.rival_info = league, rival_info

    def put(self, kind: str, data: bytes) -> tuple[str, bool]:
        with self.league.sessions() as rival:
            owner = rival.get(Racer, self.league.ids["alice"])
            crud.add_model(rival, LocalFileStore(self.root), owner, "rival", data, self.rival_info)
        return super().put(kind, data)


def test_add_model_answers_the_row_that_won_the_race(league: League) -> None:
    data = wide_mlp(64, seed=410)
    info = validate(data).info
    rows = model_rows(league)
    with league.sessions() as session:
        owner = session.get(Racer, league.ids["alice"])
        storage = RivalCommitsFirst(league, info)
        model, new = crud.add_model(session, storage, owner, "m", data, info)
        assert not new and model.name == "rival"
    assert model_rows(league) == rows + 1
    assert sum(info.archive_sha256 in p.name for p in league.storage.files("models")) == 1
