"""Training cost: where an iteration's time goes (collection vs PPO update).

Trains ``--iterations`` PPO iterations (rsl-rl, as ``slipstream train`` builds them, no
evaluations or run files) for each ``--device``, ``--workers``, ``--mode`` (sync: collect
then update; overlapped: the update runs during the next collection) and ``--critic``
value, with ``--races`` parallel races and ``--threads`` torch threads (defaults: train's;
the table shows the threads while collecting / updating), and prints one table: samples/s
end to end, collection and update seconds per iteration, the share of the wall time the
env workers and the learner's update each waited, how far the policy that starts an update
is from the one that collected its rollout (mean ``|ratio - 1|``, 0 when synchronous), the
value loss of the last iteration. The first iteration is a warm-up and is not counted.
``--profile`` writes a cProfile of one update (the last) to stdout, top functions by own
time.

Run::

    .venv/bin/python benchmarks/train_profile.py --sensors camera --iterations 3
    .venv/bin/python benchmarks/train_profile.py --sensors camera --preset "3-layer CNN" \\
        --hyperparameters hp.json --workers 0,2 --profile
    .venv/bin/python benchmarks/train_profile.py --sensors camera --critic sensors,privileged
    .venv/bin/python benchmarks/train_profile.py --sensors lidar --device cpu,cuda
    .venv/bin/python benchmarks/train_profile.py --workers 0,1,2 --mode sync,overlapped
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import time
from pathlib import Path

import torch
from harness import ResultTable, add_record_option, write

import arena
from agents import networks
from agents.action_spaces import parse_action_space_spec
from agents.hyperparameters import Hyperparameters
from agents.privileged import CriticInput
from agents.runner import RacingRunner
from agents.settings import TrainSettings, grows_batch, overlapped
from agents.vecenv import RacingVecEnv


def measure(
    args: argparse.Namespace,
    device: str,
    workers: int,
    critic: CriticInput,
    hp: Hyperparameters,
    mode: str,
) -> dict[str, float]:
    """Train ``args.iterations`` (+1 warm-up) iterations; mean timings and the last losses."""
    sensors = tuple(args.sensors.split(","))
    space = parse_action_space_spec(args.action_space)
    preset = args.preset or networks.default_preset(sensors)
    config = arena.make_config(sensors=sensors, action_space=space, mode="training", seed=0)
    env = RacingVecEnv(
        config,
        args.reward,
        num_races=args.races,
        num_workers=workers,
        privileged=critic == "privileged",
    )
    try:
        actor_cfg, critic_cfg, groups = networks.model_configs(preset, sensors, space, critic)
        asked = {"on": True, "off": False}.get(args.grow)
        if args.hyperparameters and asked is None:
            asked = False  # an explicit file is honoured as written, as by train
        grow = grows_batch(asked, device, args.steps_per_env)
        cfg = hp.to_rsl_rl(
            env.num_envs, actor_cfg, critic_cfg, groups, args.steps_per_env, grow=grow
        )
        torch.manual_seed(0)
        if mode == "auto":
            mode = "overlapped" if overlapped(None, device) else "sync"
        runner = RacingRunner(
            env, cfg, log_dir=None, device=device, threads=args.threads, sync=mode == "sync"
        )
        runner.start()
        wall = collect = update = staleness = 0.0
        losses: dict[str, float] = {}
        profiler = cProfile.Profile() if args.profile else None
        for it in range(args.iterations + 1):
            last = it == args.iterations
            if profiler is not None and last:
                profiler.enable()
            losses = runner.iteration(it)
            if it > 0:
                wall += runner.timings.wall
                collect += runner.timings.collect
                update += runner.timings.update
                staleness += runner.staleness
        if profiler is not None:
            profiler.disable()
            out = io.StringIO()
            pstats.Stats(profiler, stream=out).sort_stats("tottime").print_stats(18)
            print(f"--- profile of iteration {args.iterations} (workers={workers}) ---")
            print(out.getvalue())
        samples = cfg["num_steps_per_env"] * env.num_envs
        n = args.iterations
        algorithm = cfg["algorithm"]
        return {
            "device": device,
            "workers": workers,
            "mode": mode,
            "threads": "/".join(map(str, runner.threads)),
            "races": env.num_races,
            "preset": preset,
            "critic": critic,
            "samples": samples,
            "minibatches": algorithm["num_mini_batches"] * algorithm["num_learning_epochs"],
            "samples_per_s": samples * n / wall,
            "collect_s": collect / n,
            "update_s": update / n,
            "collect_wait": max(0.0, wall - collect) / wall,
            "update_wait": max(0.0, wall - update) / wall,
            "staleness": staleness / n,
            "value_loss": losses["value"],
        }
    finally:
        env.close()


def main() -> None:
    """Parse arguments, measure each worker count, write the table."""
    started = time.monotonic()
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--preset", default=None, help="network preset (default: by sensors)")
    parser.add_argument("--sensors", default="camera")
    parser.add_argument("--action-space", default="continuous:-30:30:0.5:2")
    parser.add_argument("--reward", default="follow_center_line")
    parser.add_argument("--iterations", type=int, default=3)
    parser.add_argument("--hyperparameters", type=Path, default=None)
    parser.add_argument("--steps-per-env", type=int, default=None)
    parser.add_argument("--workers", default="0", help="comma-separated, e.g. 0,2")
    parser.add_argument("--device", default="cpu", help="comma-separated, e.g. cpu,cuda")
    parser.add_argument(
        "--mode",
        default="auto",
        help="comma-separated: sync,overlapped (default: train's, overlapped on a GPU only)",
    )
    parser.add_argument(
        "--grow",
        choices=("auto", "on", "off"),
        default="auto",
        help="grow the iteration and minibatch with the races (default: train's, auto)",
    )
    parser.add_argument("--races", type=int, default=None, help="parallel races (default: train's)")
    parser.add_argument(
        "--critic",
        default=TrainSettings.model_fields["critic"].default,
        help="what the critic reads, comma-separated: privileged,sensors (default: train's)",
    )
    parser.add_argument(
        "--threads", type=int, default=None, help="torch threads (default: train's, auto)"
    )
    parser.add_argument("--profile", action="store_true")
    add_record_option(parser)
    args = parser.parse_args()
    hp = Hyperparameters.load(args.hyperparameters) if args.hyperparameters else None
    rows = [
        measure(args, device, int(w), critic, hp or Hyperparameters(), mode)
        for device in args.device.split(",")
        for w in args.workers.split(",")
        for mode in args.mode.split(",")
        for critic in args.critic.split(",")
    ]
    columns = (
        "device", "workers", "mode", "threads", "races", "preset", "critic", "samples/it",
        "minibatches/it", "samples/s", "collect s/it", "update s/it", "workers wait",
        "update waits", "|ratio-1|", "value loss",
    )  # fmt: skip
    table = ResultTable(
        f"training cost: {args.sensors}, {args.iterations} iterations", columns, "lrlrrllrrrrrrrrr"
    )
    for r in rows:
        table.add_row(
            str(r["device"]),
            str(r["workers"]),
            str(r["mode"]),
            r["threads"],
            str(r["races"]),
            str(r["preset"]),
            str(r["critic"]),
            str(r["samples"]),
            str(r["minibatches"]),
            f"{r['samples_per_s']:.0f}",
            f"{r['collect_s']:.2f}",
            f"{r['update_s']:.2f}",
            f"{r['collect_wait']:.0%}",
            f"{r['update_wait']:.0%}",
            f"{r['staleness']:.3f}",
            f"{r['value_loss']:.3g}",
        )
    table.notes.append(f"wall {time.monotonic() - started:.0f} s")
    write(table, args.record)


if __name__ == "__main__":
    main()
