"""Env throughput: agent-steps per second per core, step latency and memory per env.

Run: ``.venv/bin/python benchmarks/env_throughput.py [--steps N] [--repeats R]``. Single
process, so the figures are per core; each row is the run with the median step time of
``R`` runs (shared virtual machines vary by 10-20% from run to run). The "physics floor"
row is the raw PyBullet cost of the same substeps with the same cars (no sensors, rules
or params), driving apart; each config's ratio to it shows what the rest of the step
costs. "Physics in race" is the time the measured steps themselves spent in PyBullet's
``stepSimulation`` (cars that bump and respawn cost more than the floor's): the ratio
to it is the share of the step that is ours, on the same world. "Reset ms" is the mean of
``RESETS`` further resets of the same env (a new episode's world, cars and first
observations), which a PettingZoo loop pays at the end of every episode.
"""

from __future__ import annotations

import argparse
import resource
import time
import tracemalloc

import numpy as np
from harness import ResultTable, add_record_option, summary, write

import arena
from arena import world

CONFIGS = [
    ("1 car, lidar", 1, ("lidar",)),
    ("4 cars, lidar", 4, ("lidar",)),
    ("4 cars, camera+lidar", 4, ("camera", "lidar")),
    ("4 cars, stereo+lidar", 4, ("stereo", "lidar")),
]
RESETS = 10


class PhysicsClock:
    """Times ``arena.world.step`` while installed: the physics of the very steps measured,
    contacts and respawns included (the floor's cars drive apart and never touch)."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self._step = world.step

    def __enter__(self) -> PhysicsClock:
        def timed(*args: object) -> None:
            start = time.perf_counter()
            self._step(*args)
            self.seconds += time.perf_counter() - start

        world.step = timed
        return self

    def __exit__(self, *exc: object) -> None:
        world.step = self._step


def measure_env(num_cars: int, sensors: tuple[str, ...], steps: int) -> dict[str, float]:
    """Step a race with random discrete actions; reset whenever it ends."""
    race_type = "head_to_model" if num_cars > 1 else "time_trial"
    tracemalloc.start()
    env = arena.parallel_env(
        race_type=race_type, num_cars=num_cars, sensors=sensors, time_limit_s=1e6, laps=100
    )
    env.reset(seed=0)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rng = np.random.default_rng(0)
    latencies = []
    agent_steps = 0
    with PhysicsClock() as physics:
        for _ in range(steps):
            actions = {a: int(rng.integers(env.action_space(a).n)) for a in env.agents}
            start = time.perf_counter()
            env.step(actions)
            latencies.append(time.perf_counter() - start)
            agent_steps += len(actions)
            if not env.agents:
                env.reset()
    start = time.perf_counter()
    for _ in range(RESETS):
        env.reset()
    reset_s = (time.perf_counter() - start) / RESETS
    env.close()
    times = summary(latencies)
    return {
        "agent_steps_per_s": agent_steps / sum(latencies),
        "p50_ms": 1e3 * times.median,
        "p99_ms": 1e3 * times.p99,
        "step_ms": 1e3 * times.mean,
        "physics_ms": 1e3 * physics.seconds / steps,
        "mem_mb": peak / 2**20,
        "reset_ms": 1e3 * reset_s,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=600, help="control steps per config")
    parser.add_argument("--repeats", type=int, default=3, help="runs per config (median shown)")
    add_record_option(parser)
    args = parser.parse_args()
    settings = world.PhysicsSettings()
    title = f"RacingEnv throughput ({args.steps} steps, median of {args.repeats} runs, one process)"
    columns = (
        "config",
        "agent-steps/s/core",
        "step ms (mean)",
        "p50 ms",
        "p99 ms",
        "x physics floor",
        "physics ms (in race)",
        "x physics in race",
        "reset ms",
        "env alloc MB",
    )
    table = ResultTable(title, columns)
    floors = {}
    for cars in (1, 4):
        costs = [world.physics_cost(cars, settings, steps=args.steps) for _ in range(args.repeats)]
        floors[cars] = summary(costs).median
        table.add_row(
            f"physics floor, {cars} car(s)",
            f"{cars / floors[cars]:.0f}",
            f"{1e3 * floors[cars]:.2f}",
            "",
            "",
            "1.0",
            "",
            "",
            "",
            "",
        )
    for name, cars, sensors in CONFIGS:
        runs = sorted(
            (measure_env(cars, sensors, args.steps) for _ in range(args.repeats)),
            key=lambda run: run["step_ms"],
        )
        m = runs[len(runs) // 2]
        m["mem_mb"] = max(run["mem_mb"] for run in runs)  # the first run builds shared caches
        table.add_row(
            name,
            f"{m['agent_steps_per_s']:.0f}",
            f"{m['step_ms']:.2f}",
            f"{m['p50_ms']:.2f}",
            f"{m['p99_ms']:.2f}",
            f"{m['step_ms'] / (1e3 * floors[cars]):.1f}",
            f"{m['physics_ms']:.2f}",
            f"{m['step_ms'] / m['physics_ms']:.1f}",
            f"{m['reset_ms']:.1f}",
            f"{m['mem_mb']:.1f}",
        )
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    table.notes.append(f"process peak RSS {rss:.0f} MB; {settings}")
    write(table, args.record)


if __name__ == "__main__":
    main()
