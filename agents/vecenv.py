"""``RacingVecEnv``: many ``RacingEnv`` races as one rsl-rl ``VecEnv``.

Every learner-controlled car of every race is one rollout slot of the shared policy
(self-play by parameter sharing). Races run in worker processes (pipes; ``num_workers=0``
runs them in-process). Cars not driven by the learner (frozen opponents from
:mod:`agents.selfplay`) act inside the workers and are not slots; bots and boxes come
from the race config itself. Each worker loads the reward function by its path or
sample name: functions never cross process boundaries.
"""

from __future__ import annotations

import os
import time
import traceback
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from agents.imitation import EXPERT_GROUP, ExpertDriver
from agents.networks import observation_groups
from agents.privileged import PRIVILEGED_GROUP, privileged_state
from agents.processes import ignore_stop_signals, spawn_helper
from agents.rewards import resolve_reward
from agents.selfplay import Opponent, opponent_driver
from agents.settings import SLOTS_PER_WORKER
from arena.actions import DiscreteActionSpace
from arena.config import RaceConfig
from arena.env import RacingEnv
from arena.params import RewardRaised
from arena.policy import policy_action
from arena.simtrace import simtrace_row, step_facts

# Head to model: how far from a racing rival a restarted car starts, metres along the track,
# in the other lane. A learner restarts behind its rival, ahead of it and alongside it in
# turn (an opponent the other way round), so that it practises following, leading and
# racing side by side at its own pace: a learner that only ever restarts behind rarely
# sees a clear track and forgets how to drive it fast (benchmarks/RESULTS.md, "Which
# races a head-to-model learner wins").
PASS_GAP_M = 1.0
# A learner's restarts near a rival in turn, metres from it along the track: behind it (to
# pass), ahead of it (to lead and defend), alongside it (to race side by side). Alongside
# only on a track of DeepRacer's width or wider: on a narrower one the lanes' centres are
# closer than a car's width to a rival between them.
RESTART_GAPS_M = (-PASS_GAP_M, PASS_GAP_M, 0.0)
ALONGSIDE_MIN_WIDTH_M = 1.0
# Every GRID_EVERY-th restart of a learner racing frozen opponents is instead a standing
# start on a fresh grid, the learner in the back slot, as a race starts it from behind: its
# first training grid puts it in front, and restarts near a rival that is already racing
# never practise the standing start that races from behind lose most on
# (benchmarks/RESULTS.md, "Standing grid starts in training").
GRID_EVERY = 4


class RaceStepError(RuntimeError):
    """A race failed to step; the message names the race, car, step and the cause."""


@dataclass
class _Slot:
    """Book-keeping for one learner car."""

    index: int
    env: int
    car: str
    episode: int = 0
    steps: int = 0
    reward: float = 0.0
    start: float = 0.0  # simulated time the current episode started


@dataclass(frozen=True)
class _Restart:
    """How a car's next training episode starts (default: the next start point)."""

    near: tuple[str, float] | None = None  # RacingEnv.restart_car's near=(rival, gap_m)
    grid: tuple[str, ...] = ()  # RacingEnv.restart_on_grid's cars, front first


@dataclass
class StepBatch:
    """What a group of races returns after a step (numpy, slot order)."""

    obs: dict[str, np.ndarray]
    rewards: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    episodes: list[dict[str, Any]] = field(default_factory=list)


class EnvGroup:
    """Some races and their learner slots; runs inside a worker (or in-process).

    ``slot_offset`` is the global index of this group's first slot and ``total_slots`` the
    slot count of the whole vec env: a simtrace row's episode is
    ``episode_of_slot * total_slots + global_slot``, unique across groups and increasing
    per slot. ``privileged`` adds the :data:`~agents.privileged.PRIVILEGED_GROUP` to the
    observations (for a privileged critic), ``expert`` the teacher's actions
    (:data:`~agents.imitation.EXPERT_GROUP`, for imitation). ``tracks``, one per seed,
    puts each race on its own track (default: the config's).
    """

    def __init__(
        self,
        config_json: str,
        reward: str,
        seeds: list[int],
        learner_cars: list[str],
        record_simtrace: bool = True,
        slot_offset: int = 0,
        total_slots: int | None = None,
        privileged: bool = False,
        expert: bool = False,
        tracks: list[str] | None = None,
    ) -> None:
        config = RaceConfig.from_json(config_json)
        reward_fn = resolve_reward(reward, config.race_type)
        tracks = tracks or [config.track] * len(seeds)
        self.envs = [
            RacingEnv(config.model_copy(update={"seed": s, "track": t}), reward_functions=reward_fn)
            for s, t in zip(seeds, tracks, strict=True)
        ]
        self.learners = set(learner_cars)
        pairs = [(i, car) for i in range(len(self.envs)) for car in learner_cars]
        self.slots = [_Slot(slot_offset + k, i, car) for k, (i, car) in enumerate(pairs)]
        self.total_slots = total_slots or len(self.slots)
        space = config.cars[0].action_space
        self.discrete = isinstance(space, DiscreteActionSpace)
        self.record_simtrace = record_simtrace
        self.privileged = privileged
        self.experts = (
            {(s.env, s.car): ExpertDriver(self.envs[s.env].track, space) for s in self.slots}
            if expert
            else {}
        )
        self.rows: list[dict[str, Any]] = []
        self.opponents: dict[int, str] = {}  # race -> the name of its opponent
        self.drivers: dict[tuple[int, str], Any] = {}  # (race, car) -> the opponent's policy
        self.last_obs: dict[tuple[int, str], dict[str, np.ndarray]] = {}
        self.last_info: dict[tuple[int, str], dict[str, Any]] = {}
        self.restarts: Counter[tuple[int, str]] = Counter()  # restarts near a rival

    def reset(self) -> StepBatch:
        """Reset every race; returns the first observations."""
        for i, env in enumerate(self.envs):
            obs, infos = env.reset()
            for car in env.possible_agents:
                self.last_obs[(i, car)] = obs[car]
                self.last_info[(i, car)] = infos[car]
        for slot in self.slots:
            slot.start = self.envs[slot.env].time
        n = len(self.slots)
        return StepBatch(self._stack_obs(), np.zeros(n), np.zeros(n, bool), np.zeros(n, bool))

    def set_opponents(self, assignments: dict[int, Opponent]) -> None:
        """Give race ``i`` an opponent that drives each of its non-learner cars."""
        for i, opponent in assignments.items():
            env = self.envs[i]
            self.opponents[i] = opponent.name
            for car in env.config.cars:
                if car.name not in self.learners:
                    self.drivers[(i, car.name)] = opponent_driver(
                        opponent, env.track, car.action_space
                    )

    def drain_simtrace(self) -> list[dict[str, Any]]:
        """Simtrace rows recorded since the last call."""
        rows, self.rows = self.rows, []
        return rows

    def step(self, actions: np.ndarray) -> StepBatch:
        """Advance every race one control step with the slots' actions (slot order)."""
        n = len(self.slots)
        rewards, terminated, truncated = np.zeros(n), np.zeros(n, bool), np.zeros(n, bool)
        episodes: list[dict[str, Any]] = []
        slot_of = {(s.env, s.car): k for k, s in enumerate(self.slots)}
        for i, env in enumerate(self.envs):
            commands = {car: self._action(i, car, actions, slot_of) for car in env.agents}
            try:
                obs, rew, term, trunc, infos = env.step(commands)
            except RewardRaised as exc:  # the user's reward function raised
                raise RaceStepError(f"race {i}: {exc}") from exc.__cause__
            except Exception as exc:  # e.g. the arena's check of a reward's value
                raise RaceStepError(f"race {i}: {type(exc).__name__}: {exc}") from exc
            poses = env.car_poses()
            for car in commands:
                self.last_obs[(i, car)] = obs[car]
                self.last_info[(i, car)] = infos[car]
                k = slot_of.get((i, car))
                if k is not None:
                    slot = self.slots[k]
                    slot.steps += 1
                    slot.reward += rew[car]
                    rewards[k], terminated[k], truncated[k] = rew[car], term[car], trunc[car]
                    if self.record_simtrace:
                        facts = step_facts(infos[car], poses[car], commands[car], rew[car])
                        episode = slot.episode * self.total_slots + slot.index
                        self.rows.append(simtrace_row(facts, episode, wall_clock=time.time()))
                    if term[car] or trunc[car]:
                        episodes.append(self._episode_stats(i, car, slot, infos[car]))
            ended = [car for car in commands if term[car] or trunc[car]]
            self._restart(i, sorted(ended, key=lambda c: c not in self.learners), slot_of)
        return StepBatch(self._stack_obs(), rewards, terminated, truncated, episodes)

    def _restart(self, i: int, ended: list[str], slot_of: dict[tuple[int, str], int]) -> None:
        """Start new episodes for race ``i``'s cars whose episodes ended (learners first)."""
        env = self.envs[i]
        for car in ended:
            if car in env.agents:
                continue  # already back, on a grid behind it with a learner
            restart = self._restart_kind(i, car)
            starts = (
                env.restart_on_grid(restart.grid)
                if restart.grid
                else {car: env.restart_car(car, restart.near)}
            )
            for started, (first, info) in starts.items():
                self.last_obs[(i, started)] = first
                self.last_info[(i, started)] = info
                k = slot_of.get((i, started))
                if k is not None:
                    self.slots[k].start = env.time
                    if self.experts:
                        self.experts[(i, started)].reset()
                elif (i, started) in self.drivers:
                    self.drivers[(i, started)].reset()

    def _restart_kind(self, i: int, car: str) -> _Restart:
        """How head-to-model race ``i`` restarts ``car``: beside a racing rival, in turn
        :data:`PASS_GAP_M` behind it, as far ahead of it and alongside it (a learner behind
        first, an opponent ahead first); but a learner racing only frozen opponents starts
        every :data:`GRID_EVERY`-th restart, one from behind, standing behind them on a
        fresh grid. Other race types: the next start point."""
        env = self.envs[i]
        if env.config.race_type != "head_to_model":
            return _Restart()
        learner = car in self.learners
        rivals = [c for c in env.agents if c != car and (learner or c in self.learners)]
        if not rivals:
            return _Restart()
        count = self.restarts[(i, car)]
        self.restarts[(i, car)] += 1
        if learner and count % GRID_EVERY == 0 and self.learners.isdisjoint(rivals):
            return _Restart(grid=(*rivals, car))
        gaps = RESTART_GAPS_M if env.track.width >= ALONGSIDE_MIN_WIDTH_M else RESTART_GAPS_M[:2]
        gap = gaps[count % len(gaps)]
        return _Restart(near=(rivals[0], gap if learner else -gap))

    def _action(
        self, i: int, car: str, actions: np.ndarray, slot_of: dict[tuple[int, str], int]
    ) -> Any:
        k = slot_of.get((i, car))
        if k is not None:
            return int(actions[k]) if self.discrete else actions[k]
        driver = self.drivers.get((i, car))
        if driver is None:
            raise RuntimeError(f"race {i}: car {car!r} has neither a learner slot nor an opponent")
        return policy_action(driver, self.last_obs[(i, car)], self.last_info[(i, car)])

    def _episode_stats(self, i: int, car: str, slot: _Slot, info: dict[str, Any]) -> dict:
        lap_complete = info["episode_status"] == "lap_complete"
        stats = {
            "reward": slot.reward,
            "steps": slot.steps,
            "progress": 100.0 if lap_complete else float(info["progress"]),
            "lap_complete": lap_complete,
            "status": info["episode_status"],
            "start_time": slot.start,
            "end_time": float(info["time"]),
        }
        if i in self.opponents:
            rivals = [
                self.last_info[(i, c)]["progress"]
                for c in self.envs[i].possible_agents
                if c not in self.learners
            ]
            stats["opponent"] = self.opponents[i]
            stats["win"] = stats["lap_complete"] or stats["progress"] > max(rivals, default=0.0)
        slot.episode += 1
        slot.steps, slot.reward = 0, 0.0
        return stats

    def _stack_obs(self) -> dict[str, np.ndarray]:
        first = self.last_obs[(self.slots[0].env, self.slots[0].car)]
        groups = {
            name: np.stack([self.last_obs[(s.env, s.car)][name] for s in self.slots])
            for name in first
        }
        if self.privileged:
            groups[PRIVILEGED_GROUP] = np.stack(
                [
                    privileged_state(
                        self.envs[s.env].track, self.last_info[(s.env, s.car)]["params"]
                    )
                    for s in self.slots
                ]
            )
        if self.experts:
            groups[EXPERT_GROUP] = np.stack(
                [
                    self.experts[(s.env, s.car)].action(self.last_info[(s.env, s.car)]["params"])
                    for s in self.slots
                ]
            )
        return groups

    def close(self) -> None:
        """Close every race."""
        for env in self.envs:
            env.close()


def _worker(conn: Any, kwargs: dict[str, Any]) -> None:
    ignore_stop_signals()  # the trainer handles them and closes this worker
    try:
        group = EnvGroup(**kwargs)
        conn.send(("ok", None))
    except Exception:
        conn.send(("error", traceback.format_exc(limit=3)))
        return
    while True:
        command, args = conn.recv()
        if command == "close":
            group.close()
            conn.send(("ok", None))
            return
        try:
            conn.send(("ok", getattr(group, command)(*args)))
        except RaceStepError as exc:
            conn.send(("error", str(exc)))
        except Exception as exc:
            conn.send(("error", f"{type(exc).__name__}: {exc}"))


class RacingVecEnv(VecEnv):
    """rsl-rl ``VecEnv`` over ``num_races`` copies of a training race.

    Args:
        config: the race (``mode="training"``); its cars' sensors and action space are the
            learner's.
        reward: path of a reward-function file or a bundled sample's name.
        num_races: race instances (default: enough for
            :data:`~agents.settings.SLOTS_PER_WORKER` learner cars per worker, or
            in-process, and at least one race per track).
        num_workers: worker processes (default ``os.cpu_count()``; 0 = in-process).
        learner_cars: cars the shared policy drives (default: all); the others need
            opponents (:meth:`set_opponents`).
        record_simtrace: keep per-step simtrace rows (:meth:`drain_simtrace`).
        privileged: add the privileged-state group (``agents.privileged``) to the
            observations, for a critic that reads it.
        expert: add the teacher's actions (``agents.imitation``), for imitation.
        also_tracks: further tracks: the races take ``config.track`` and these in turn,
            and there are at least as many races as tracks.
    """

    def __init__(
        self,
        config: RaceConfig,
        reward: str,
        *,
        num_races: int | None = None,
        num_workers: int | None = None,
        learner_cars: list[str] | None = None,
        device: str = "cpu",
        record_simtrace: bool = True,
        privileged: bool = False,
        expert: bool = False,
        also_tracks: Sequence[str] = (),
    ) -> None:
        if config.mode != "training":
            raise ValueError("RacingVecEnv needs a training-mode race config")
        workers = (os.cpu_count() or 1) if num_workers is None else num_workers
        tracks = [config.track, *also_tracks]
        self.learner_cars = learner_cars or [c.name for c in config.cars]
        per_worker = max(1, SLOTS_PER_WORKER // len(self.learner_cars))
        self.num_races = num_races or max(per_worker * max(1, workers), len(tracks))
        if self.num_races < len(tracks):
            raise ValueError(
                f"{len(tracks)} tracks need at least {len(tracks)} races, one on each; "
                f"got {self.num_races}"
            )
        race_tracks = [tracks[i % len(tracks)] for i in range(self.num_races)]
        self.config = config
        self.device = device
        self.cfg = config.model_dump(mode="json")
        space = config.cars[0].action_space
        self.discrete = isinstance(space, DiscreteActionSpace)
        self.num_actions = space.n if self.discrete else 2
        self.num_envs = self.num_races * len(self.learner_cars)
        self.max_episode_length = int(config.time_limit_s * config.physics.control_hz)
        self.episode_length_buf = torch.zeros(self.num_envs, dtype=torch.long)
        self._episodes: list[dict[str, Any]] = []
        seeds = [config.seed + 1000 * i for i in range(self.num_races)]
        shares = min(workers, self.num_races) if workers > 0 else 1
        self._races_of = [list(range(self.num_races))[w::shares] for w in range(shares)]
        per_car = len(self.learner_cars)
        offsets = np.cumsum([0] + [len(r) * per_car for r in self._races_of]).tolist()
        kwargs = [
            {
                "config_json": config.to_json(),
                "reward": reward,
                "seeds": [seeds[i] for i in races],
                "tracks": [race_tracks[i] for i in races],
                "learner_cars": self.learner_cars,
                "record_simtrace": record_simtrace,
                "slot_offset": offsets[w],
                "total_slots": self.num_envs,
                "privileged": privileged,
                "expert": expert,
            }
            for w, races in enumerate(self._races_of)
        ]
        self._local: EnvGroup | None = None
        self._conns: list[Any] = []
        self._procs: list[Any] = []
        try:
            if workers == 0:
                self._local = EnvGroup(**kwargs[0])
            else:
                self._start_workers(kwargs)
            self._obs = self._to_tensordict(self._call("reset"))
        except BaseException:  # a worker failed to start, or Ctrl-C: stop the others
            self.close()
            raise

    # ---------------------------------------------------------------- workers
    def _start_workers(self, kwargs: list[dict[str, Any]]) -> None:
        """Spawn the workers (:func:`agents.processes.spawn_helper`: the stop signals are
        the trainer's, which closes them)."""
        for kw in kwargs:
            conn, proc = spawn_helper(_worker, kw)
            self._conns.append(conn)
            self._procs.append(proc)
        for conn in self._conns:
            self._receive(conn)

    @staticmethod
    def _receive(conn: Any) -> Any:
        try:
            status, payload = conn.recv()
        except EOFError:
            raise RuntimeError("a racing worker exited unexpectedly") from None
        if status == "error":
            raise RuntimeError(f"racing worker failed: {payload}")
        return payload

    def _call(self, command: str, per_worker_args: list[tuple] | None = None) -> list[Any]:
        """Run ``command`` on every group; returns the results in group order."""
        groups = len(self._conns) or 1
        args = per_worker_args or [()] * groups
        if self._local is not None:
            return [getattr(self._local, command)(*args[0])]
        for conn, a in zip(self._conns, args, strict=True):
            conn.send((command, a))
        results, failure = [], None
        for conn in self._conns:  # read every reply, so none is left in a pipe
            try:
                results.append(self._receive(conn))
            except RuntimeError as exc:
                failure = failure or exc
        if failure is not None:
            raise failure
        return results

    # ------------------------------------------------------------- rsl-rl API
    @property
    def num_workers(self) -> int:
        """Worker processes stepping the races (0: in-process)."""
        return len(self._procs)

    def get_observations(self) -> TensorDict:
        """The current observations (a fresh TensorDict of sensor groups)."""
        return self._obs.clone()

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """Step every race with the slots' actions (one-hot rows or 2 continuous values)."""
        acts = actions.detach().to("cpu")
        if self.discrete:
            values = acts.argmax(dim=-1).numpy()
        else:
            values = acts.clamp(-1.0, 1.0).numpy().astype(np.float32)
        per_group, start = [], 0
        for races in self._races_of:
            count = len(races) * len(self.learner_cars)
            per_group.append((values[start : start + count],))
            start += count
        batches = self._call("step", per_group)
        self._obs = self._to_tensordict(batches)
        rewards = torch.tensor(np.concatenate([b.rewards for b in batches]), dtype=torch.float32)
        terminated = torch.tensor(np.concatenate([b.terminated for b in batches]))
        truncated = torch.tensor(np.concatenate([b.truncated for b in batches]))
        dones = terminated | truncated
        self.episode_length_buf = torch.where(dones, 0, self.episode_length_buf + 1)
        episodes = [e for b in batches for e in b.episodes]
        self._episodes.extend(episodes)
        extras: dict[str, Any] = {"time_outs": truncated.clone()}
        if episodes:
            extras["log"] = {
                "/episode/reward": torch.tensor([e["reward"] for e in episodes]),
                "/episode/progress": torch.tensor([e["progress"] for e in episodes]),
                "/episode/lap_completion": torch.tensor(
                    [float(e["lap_complete"]) for e in episodes]
                ),
            }
        return self._obs.clone(), rewards, dones, extras

    # ------------------------------------------------------------------ extras
    def pop_episodes(self) -> list[dict[str, Any]]:
        """Per-episode stats (reward, steps, progress, lap_complete, ...) since last call."""
        episodes, self._episodes = self._episodes, []
        return episodes

    def drain_simtrace(self) -> list[dict[str, Any]]:
        """Simtrace rows of every slot since the last call."""
        return [row for rows in self._call("drain_simtrace") for row in rows]

    def set_opponents(self, assignments: dict[int, Opponent]) -> None:
        """Assign opponents to races (global race index)."""
        per_group = [
            ({local: assignments[g] for local, g in enumerate(races) if g in assignments},)
            for races in self._races_of
        ]
        self._call("set_opponents", per_group)

    def close(self) -> None:
        """Stop the workers and close every race."""
        if self._local is not None:
            self._local.close()
            self._local = None
        for conn in self._conns:
            try:
                conn.send(("close", ()))
                while conn.poll(5) and conn.recv() != ("ok", None):
                    pass  # a reply the caller did not read (Ctrl-C mid-step)
            except (OSError, EOFError):
                pass
            conn.close()
        for proc in self._procs:
            proc.join(timeout=5)
            if proc.is_alive():
                proc.kill()  # it ignores SIGTERM
                proc.join(timeout=5)
        self._conns, self._procs = [], []

    def _to_tensordict(self, batches: list[StepBatch]) -> TensorDict:
        arrays = {name: np.concatenate([b.obs[name] for b in batches]) for name in batches[0].obs}
        return observation_groups(arrays, self.device)
