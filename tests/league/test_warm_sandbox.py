"""The warm race sandbox: one child, many races, each under its own limits, nothing shared.

Races are short (8 s of simulated time) on real plans: a lidar model against the pursuit bot
(grid order and start jitter drawn from the seed), a camera model among obstacles, and a
lidar time trial. No database is needed.
"""

from __future__ import annotations

import os
import time

import pytest

import arena
from arena.config import RaceConfig
from league.jobs.evaluation import CarPlan, RacePlan, decode_plan, encode_plan
from league.jobs.sandbox import SandboxError, SandboxLimits, WarmSandbox, run_limited
from league.jobs.worker import answer_request, race_answer
from submissions import InvalidSubmission, load_policy
from tests.league.conftest import policy_onnx
from tests.submissions.hostile_models import broadcast_bomb
from tests.submissions.test_stack_size import camera_graph
from tests.submissions.test_support import pack_bytes

LIMITS = SandboxLimits(memory_mb=512, cpu_seconds=60, wall_seconds=60.0)
# The wall limit is only a hang guard here: 15 times the 2 s of CPU that "spin" must reach.
QUICK = SandboxLimits(memory_mb=256, cpu_seconds=2, wall_seconds=30.0)
KEPT: list[bytearray] = []


def plans() -> list[RacePlan]:
    """Three different races."""
    lidar = pack_bytes(policy_onnx(1), sensors=("lidar",))
    camera = pack_bytes(camera_graph(1), sensors=("camera",))
    versus = RaceConfig.build(
        race_type="head_to_model",
        cars=[{"name": "entry1", "sensors": ("lidar",)}, {"name": "bot1"}],
        time_limit_s=8.0,
        seed=3,
    )
    boxes = arena.make_config(
        race_type="object_avoidance", sensors=("camera",), time_limit_s=8.0, seed=5
    )
    boxes = boxes.model_copy(update={"cars": (boxes.cars[0].model_copy(update={"name": "e2"}),)})
    trial = arena.make_config(time_limit_s=8.0, seed=7)
    trial = trial.model_copy(update={"cars": (trial.cars[0].model_copy(update={"name": "e3"}),)})
    return [
        RacePlan(versus, (CarPlan("entry1", 1, model=lidar), CarPlan("bot1", None, bot="pursuit"))),
        RacePlan(boxes, (CarPlan("e2", 2, model=camera),)),
        RacePlan(trial, (CarPlan("e3", 3, model=lidar),)),
    ]


def test_a_plan_survives_its_trip_to_the_child() -> None:
    for plan in plans():
        assert decode_plan(encode_plan(plan)) == plan


def test_stored_models_skip_only_the_behaviour_stage() -> None:
    """A race re-runs the archive, metadata and static graph checks, not the sample runs."""
    with pytest.raises(InvalidSubmission, match="tensors too large for a race"):
        load_policy(broadcast_bomb(16384), run_policy=False)  # refused from its shapes, never built
    policy = load_policy(plans()[2].cars[0].model or b"", non_finite="raise", run_policy=False)
    assert policy.info.latency_ms is None and policy.non_finite == "raise"


def test_races_in_one_warm_child_equal_races_in_fresh_children() -> None:
    first, second, third = plans()
    sandbox = WarmSandbox(answer_request, LIMITS)
    try:
        warm = [sandbox.run(encode_plan(p)) for p in (first, second, first, third)]
        assert sandbox.forks == 1 and sandbox.runs == 4
    finally:
        sandbox.close()
    fresh = [run_limited(lambda p=p: race_answer(p), LIMITS) for p in (first, second, third)]
    assert warm[0] == warm[2] == fresh[0]
    assert warm[1] == fresh[1]
    assert warm[3] == fresh[2]
    assert warm[0]["steps"] == 120 and warm[1]["obstacles"]


def handler(request: bytes) -> object:
    """Requests for the limit tests: a command, answered or misbehaving."""
    command = request.decode()
    if command == "pid":
        return os.getpid()
    if command == "sleep":
        time.sleep(3600)
    if command.startswith("spin"):
        end = time.process_time() + float(command[4:] or "inf")
        while time.process_time() < end:
            pass
        return "spun"
    if command.startswith("alloc"):
        return len(bytearray(int(command[5:]) * 1024 * 1024))
    if command.startswith("keep"):  # a leak: what the high-water mark is for
        KEPT.append(bytearray(int(command[4:]) * 1024 * 1024))
        return len(KEPT)
    if command == "boom":
        raise ValueError("bad ruleset")
    if command == "abort":
        os.abort()
    raise AssertionError(command)


@pytest.mark.parametrize(
    ("command", "kind", "message"),
    [
        ("sleep", "wall", "wall-time limit of 1.5 s"),
        ("spin", "cpu", "CPU-time limit of 2 s"),
        ("alloc4096", "memory", "memory limit of 256 MiB"),
        ("boom", "error", "ValueError: bad ruleset"),
        ("abort", "crash", "SIGABRT"),
    ],
)
def test_a_warm_child_that_breaks_a_limit_fails_like_a_fresh_one(
    command: str, kind: str, message: str
) -> None:
    limits = SandboxLimits(256, 2, 1.5) if command == "sleep" else QUICK
    sandbox = WarmSandbox(handler, limits)
    try:
        before = sandbox.run(b"pid")
        with pytest.raises(SandboxError, match=message) as warm:
            sandbox.run(command.encode())
        assert warm.value.kind == kind and sandbox.pid is None
        with pytest.raises(SandboxError, match=message) as fresh:
            run_limited(lambda: handler(command.encode()), limits)
        assert (fresh.value.kind, str(fresh.value)) == (kind, str(warm.value))
        assert sandbox.run(b"pid") != before and sandbox.forks == 2  # a new child goes on
    finally:
        sandbox.close()


def test_limits_are_per_race_not_per_child() -> None:
    sandbox = WarmSandbox(handler, QUICK)
    try:
        for _ in range(2):  # 2.4 s of CPU and 2 x 200 MiB in all, each race within its limits
            assert sandbox.run(b"spin1.2") == "spun"
            assert sandbox.run(b"alloc200") == 200 * 1024 * 1024
        assert sandbox.forks == 1
    finally:
        sandbox.close()


def _wait_until_dead(pid: int, timeout_s: float = 10.0) -> None:
    """Until ``pid`` has exited (a zombie its parent has not reaped): a SIGKILL takes
    effect when the kernel next schedules the process, later than 0.1 s on a busy machine."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with open(f"/proc/{pid}/stat") as handle:
            if handle.read().rsplit(")", 1)[1].split()[0] == "Z":
                return
        time.sleep(0.01)
    raise AssertionError(f"process {pid} still alive {timeout_s} s after SIGKILL")


def test_children_are_replaced_after_max_runs_on_high_water_and_when_killed_idle() -> None:
    sandbox = WarmSandbox(handler, QUICK, max_runs=2, high_water_mb=64)
    try:
        pids = [sandbox.run(b"pid") for _ in range(4)]
        assert pids[0] == pids[1] != pids[2] == pids[3] and sandbox.forks == 2
        sandbox.run(b"pid")
        os.kill(sandbox.pid, 9)  # killed between races: the next race gets a new child
        _wait_until_dead(sandbox.pid)
        assert sandbox.run(b"pid") not in pids and sandbox.forks == 4
        assert sandbox.run(b"keep100") == 1 and sandbox.pid is None  # over the high water
        assert sandbox.run(b"keep10") == 1 and sandbox.forks == 5  # a new child: nothing kept
    finally:
        sandbox.close()
