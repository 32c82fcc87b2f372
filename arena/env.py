"""``RacingEnv``: several cars racing on a track, as a PettingZoo ``ParallelEnv``.

One PyBullet DIRECT client per env; the world is rebuilt on every ``reset`` so that a
(config, seed, actions) triple always gives the same trajectory. Each control step:
actions become steering and wheel-speed commands, physics runs its substeps, the
rules judge every car (see :mod:`arena.rules`) and each car gets its sensors'
observation, its reward from its ``reward_function(params)`` and an info dict carrying
the DeepRacer ``params``, all from that one world state; only then are penalised cars
respawned and held, and served ones released (race mode), for the next step.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from arena import world
from arena.camera import Box3D, CameraRenderer
from arena.car import Car, CarSnapshot
from arena.car_spec import DEFAULT_CAR
from arena.config import ConfigError, RaceConfig, resolve_track
from arena.drivers import LaneFollower
from arena.lidar import (
    Lidar,
    clip_lidar,
    discretized_sector_lidar,
    lidar_reach,
    sector_lidar,
)
from arena.params import ObjectsView, build_params, call_reward
from arena.rewards import follow_center_line
from arena.rules import REJOIN_S, CarRecord, ContactParty, EpisodeStatus, Measurement, RuleBook
from arena.sensors_spec import IMAGE_SENSORS, observation_space
from arena.spawn import (
    RESPAWN_CLEARANCE_M,
    Placement,
    bot_places,
    car_footprint,
    car_grid,
    grid_slots,
    is_clear,
    nearest_lane,
    obstacle_places,
    other_lane,
    rectangle,
    respawn_place,
    start_arc,
)
from arena.spawn import place as place_at
from tracks.track import Projection, Track

RewardFunction = Callable[[dict[str, Any]], float]
CAR_COLORS = [
    (0.85, 0.1, 0.1, 1.0),
    (0.1, 0.35, 0.9, 1.0),
    (0.1, 0.7, 0.2, 1.0),
    (0.9, 0.75, 0.1, 1.0),
    (0.6, 0.2, 0.8, 1.0),
    (0.1, 0.75, 0.75, 1.0),
    (0.95, 0.5, 0.1, 1.0),
    (0.5, 0.5, 0.5, 1.0),
]
BOT_COLOR = (0.15, 0.15, 0.15, 1.0)
CAR_GRAY, BOT_GRAY, BOX_GRAY = 90, 40, 200
PARK_DISTANCE = 1000.0
# Spawn-key tags of the random streams drawn beside the episode's main one (``self.rng``).
GRID_STREAM, NOISE_STREAM = 0, 1
# Lidar culling circles reach this far beyond an object's footprint: a car tilting in a
# collision leans a little outside it.
LIDAR_CULL_MARGIN = 0.03


_CAMERAS: dict[bytes, CameraRenderer] = {}
CAMERA_CACHE_SIZE = 4


def track_camera(track: Track) -> CameraRenderer:
    """The camera renderer of ``track``'s geometry, built once per process and reused by
    every env on it (it holds no race state; a few recent tracks are kept)."""
    arrays = (track.waypoints, track.left, track.right)
    key = hashlib.sha256(b"".join(np.ascontiguousarray(a).tobytes() for a in arrays)).digest()
    camera = _CAMERAS.pop(key, None) or CameraRenderer(track)
    _CAMERAS[key] = camera  # most recent last
    while len(_CAMERAS) > CAMERA_CACHE_SIZE:
        del _CAMERAS[next(iter(_CAMERAS))]
    return camera


def substream(seq: np.random.SeedSequence, *key: int) -> np.random.SeedSequence:
    """The seed sequence ``key`` below ``seq``: independent of ``seq``'s own stream."""
    return np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, *key))


def car_noise_rng(seq: np.random.SeedSequence, name: str) -> np.random.Generator:
    """A car's actuation-noise stream, keyed by its name: the same whatever the other cars."""
    name_key = int.from_bytes(hashlib.sha256(name.encode()).digest()[:8], "little")
    return np.random.default_rng(substream(seq, NOISE_STREAM, name_key))


@dataclass
class _Obstacle:
    body: int
    place: Placement
    lane: str
    size: tuple[float, float, float]


@dataclass
class _Bot:
    car: Car
    driver: LaneFollower
    next_change: float


@dataclass(frozen=True)
class _Scene:
    """Objects on track at one instant: obstacles, bots, then the racing cars front to back
    on the grid, each with its name (``box<i>``, ``bot<i>`` or the car's), its body and
    the controlled car it is (if any)."""

    objects: ObjectsView
    projection: Projection
    boxes: list[Box3D]
    owners: list[str | None]
    names: list[str]
    bodies: list[int]
    targets: np.ndarray


@dataclass(frozen=True)
class _Contact:
    """One contact of a car in a step: the other party, and whether this car caused it."""

    other: str
    at_fault: bool
    obstacle: int | None = None  # the box's body, when the other party is a box


@dataclass(frozen=True)
class _Verdict:
    """What the judging of one step found for one car (nothing moved yet)."""

    params: dict[str, Any]
    contacts: list[_Contact]
    status: EpisodeStatus
    offset: float
    penalised: bool
    released: bool


@dataclass
class _Live:
    """One controlled car's simulation objects and last measurements."""

    car: Car
    record: CarRecord
    command: tuple[float, float] = (0.0, 0.0)
    hold: Placement | None = None
    last_point: np.ndarray | None = None
    parked: bool = False
    released_at: float | None = None


class RacingEnv(ParallelEnv):
    """DeepRacer-style racing for 1-8 controlled cars (PettingZoo parallel API).

    Args:
        config: the race (track, rules, cars, seed).
        reward_functions: one ``reward_function(params) -> float`` for every car, or a
            mapping from car name to its function; defaults to following the centre line.
        render_mode: ``None`` or ``"rgb_array"`` (a top-down picture of the race).
    """

    metadata: ClassVar[dict[str, Any]] = {
        "name": "slipstream_racing_v0",
        "render_modes": ["rgb_array"],
        "render_fps": 15,
        "is_parallelizable": True,
    }

    def __init__(
        self,
        config: RaceConfig,
        reward_functions: RewardFunction | Mapping[str, RewardFunction] | None = None,
        render_mode: str | None = None,
    ) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ConfigError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.config = config
        self.render_mode = render_mode
        self.track, self.is_reversed = resolve_track(config)
        self.possible_agents = [car.name for car in config.cars]
        self.agents: list[str] = []
        self._car_configs = {car.name: car for car in config.cars}
        # How far each lidar car's views look (cars without a lidar are absent).
        self._lidar_reach = {
            c.name: lidar_reach(c.sensors, c.lidar_config)
            for c in config.cars
            if any("lidar" in s for s in c.sensors)
        }
        self._rewards = self._reward_table(reward_functions)
        self._obs_spaces = {
            c.name: observation_space(c.sensors, c.lidar_config, c.stack_size) for c in config.cars
        }
        # Cars that stack frames, and their last stacked observation (oldest frame first).
        self._stack_sizes = {c.name: c.stack_size for c in config.cars if c.stack_size > 1}
        self._stacks: dict[str, dict[str, np.ndarray]] = {}
        self._act_spaces = {c.name: c.action_space.gym_space() for c in config.cars}
        self._physics = world.PhysicsSettings(
            control_hz=config.physics.control_hz, physics_hz=config.physics.physics_hz
        )
        self._rules = RuleBook(
            track=self.track,
            mode=config.mode,
            laps=config.laps,
            penalties=config.penalties,
            max_resets=config.max_resets,
            time_limit_s=config.time_limit_s,
        )
        self._needs_camera = any(s in IMAGE_SENSORS for c in config.cars for s in c.sensors)
        self._camera = track_camera(self.track) if self._needs_camera else None
        self._waypoints = [tuple(map(float, w)) for w in self.track.waypoints]
        self._check_fits()
        self._client: int | None = None
        self._episode = -1
        self._renderer = None
        self.time = 0.0

    # ------------------------------------------------------------------ spaces
    def observation_space(self, agent: str) -> spaces.Dict:
        """The agent's observation space: a Dict with one entry per sensor."""
        return self._obs_spaces[agent]

    def action_space(self, agent: str) -> spaces.Space:
        """``Discrete(n)`` for a discrete action list, ``Box(-1, 1, (2,))`` for continuous."""
        return self._act_spaces[agent]

    # ------------------------------------------------------------------- setup
    def _reward_table(
        self, reward_functions: RewardFunction | Mapping[str, RewardFunction] | None
    ) -> dict[str, RewardFunction]:
        if reward_functions is None:
            return dict.fromkeys(self.possible_agents, follow_center_line)
        if callable(reward_functions):
            return dict.fromkeys(self.possible_agents, reward_functions)
        unknown = set(reward_functions) - set(self.possible_agents)
        if unknown:
            raise ConfigError(f"reward functions given for unknown cars {sorted(unknown)}")
        return {a: reward_functions.get(a, follow_center_line) for a in self.possible_agents}

    def _check_fits(self) -> None:
        """Fail before anything starts when obstacles or bots cannot fit on the track."""
        rng = np.random.default_rng(0)
        if self.config.obstacles is not None:
            obstacle_places(self.config.obstacles, self.track, 0.0, rng)
        if self.config.bots is not None:
            bot_places(self.config.bots.count, self.config.bots.min_gap_m, self.track, 0.0)

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Start a new race or training episode; ``seed`` defaults to the config's seed."""
        if seed is None:
            seed = self.config.seed if self._episode < 0 else None
        if seed is not None:
            self._seed_seq = np.random.SeedSequence(seed)
            self._episode = -1
        self._episode += 1
        episode_seq = self._seed_seq.spawn(1)[0]
        self.rng = np.random.default_rng(episode_seq)
        self._grid_rng = np.random.default_rng(substream(episode_seq, GRID_STREAM))
        noisy = self.possible_agents if self.config.active_variation.has_actuation_noise else []
        self._noise = {agent: car_noise_rng(episode_seq, agent) for agent in noisy}
        self.time = 0.0  # before the world: bots draw their first lane change from it
        self._build_world()
        self.agents = list(self.possible_agents)
        observations = self._observe(fresh=True)
        infos = {a: self._info(a, self._initial_params(a)) for a in self.agents}
        return observations, infos

    def _build_world(self) -> None:
        self._client = client = world.create_world(self._physics, self._client)
        arc0 = start_arc(self.config, self.track, self._episode)
        self._obstacles = []
        if self.config.obstacles is not None:
            size = self.config.obstacles.size
            for place, lane in obstacle_places(self.config.obstacles, self.track, arc0, self.rng):
                body = world.add_box(client, place.x, place.y, place.yaw, size=size)
                self._obstacles.append(_Obstacle(body, place, lane, size))
        self._bots = []
        if self.config.bots is not None:
            bots = self.config.bots
            for place, lane in bot_places(bots.count, bots.min_gap_m, self.track, arc0):
                car = Car(client, DEFAULT_CAR, place.x, place.y, place.yaw, color=BOT_COLOR)
                driver = LaneFollower(self.track, bots.speed, lane=lane)
                self._bots.append(_Bot(car, driver, self._next_lane_change()))
        places = dict(
            zip(
                self.possible_agents,
                car_grid(self.config, self.track, arc0, self._grid_rng),
                strict=True,
            )
        )
        # Bodies are made front to back: the physics follows the bodies' order, and must
        # not follow the order the cars are listed in. Scenes and lidar batches use it too.
        self._order = sorted(
            self.possible_agents,
            key=lambda a: (-self.track.arc_delta(arc0, places[a].arc), places[a].offset),
        )
        built: dict[str, _Live] = {}
        for agent in self._order:
            place = places[agent]
            color = CAR_COLORS[self.possible_agents.index(agent)]
            car = Car(client, DEFAULT_CAR, place.x, place.y, place.yaw, color=color)
            point = car.model_point()
            record = self._rules.start(self._arc_of(point), 0.0)
            built[agent] = _Live(car, record, last_point=point)
        self._cars = {agent: built[agent] for agent in self.possible_agents}
        self._lidar = Lidar(client)
        self._car_episodes = dict.fromkeys(self.possible_agents, 0)
        self._scene_cache: _Scene | None = None
        self._snaps: dict[int, CarSnapshot] = {}
        self._obstacle_bodies = {o.body: o for o in self._obstacles}
        self._last_offsets: dict[int, float] = {}

    def _next_lane_change(self) -> float:
        bots = self.config.bots
        assert bots is not None
        return self.time + float(self.rng.uniform(bots.lane_change_min_s, bots.lane_change_max_s))

    # -------------------------------------------------------------------- step
    def step(self, actions: Mapping[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Advance every live car by one control period (1/15 s by default)."""
        if self._client is None:
            raise RuntimeError("call reset() before step()")
        for agent in self.agents:
            live = self._cars[agent]
            if agent not in actions:
                raise ValueError(f"no action given for car {agent!r}")
            steer, speed = self._car_configs[agent].action_space.to_command(actions[agent])
            live.command = (steer, speed)
            if live.hold is None:
                live.car.apply_command(*self._actuated(agent, steer, speed))
        self._drive_bots()
        world.step(self._client, self._physics)
        self._forget_poses()
        self.time += self.config.control_dt
        for agent in self.agents:
            hold = self._cars[agent].hold
            if hold is not None:
                self._cars[agent].car.hold(hold.x, hold.y, hold.yaw)

        verdicts = self._judge()
        observations = self._observe()
        rewards, terminations, truncations, infos = {}, {}, {}, {}
        for agent in self.agents:
            live = self._cars[agent]
            params = verdicts[agent].params
            rewards[agent] = call_reward(self._rewards[agent], agent, live.record.steps, params)
            terminations[agent] = live.record.done and not live.record.truncated
            truncations[agent] = live.record.truncated
            infos[agent] = self._info(agent, params, verdicts[agent].contacts)
        self._respawn_and_release(verdicts)
        for agent in list(self.agents):
            if self._cars[agent].record.done:
                self._park(agent)
        self.agents = [a for a in self.agents if not self._cars[a].record.done]
        return observations, rewards, terminations, truncations, infos

    def _actuated(self, agent: str, steer: float, speed: float) -> tuple[float, float]:
        """The command the car carries out: the policy's plus the ruleset's actuation noise,
        drawn from the car's own stream (the car clips it to its limits)."""
        noise = self._noise.get(agent)
        if noise is None:
            return steer, speed
        variation = self.config.active_variation
        steer_noise, speed_noise = noise.standard_normal(2)
        return (
            steer + variation.steering_noise_deg * float(steer_noise),
            speed * (1.0 + variation.speed_noise_frac * float(speed_noise)),
        )

    def _drive_bots(self) -> None:
        for bot in self._bots:
            if self.time >= bot.next_change:
                bot.driver.lane = other_lane(bot.driver.lane)
                bot.next_change = self._next_lane_change()
            state = self._snap(bot.car).state
            bot.car.apply_command(*bot.driver.command(state.x, state.y, state.yaw))

    def _judge(self) -> dict[str, _Verdict]:
        """Measure every live car, judge its contacts, apply the rules and build its params,
        all from the world as physics left it: nothing moves here, so no car's verdict
        depends on the order the cars are judged in (see :meth:`_respawn_and_release`)."""
        agents = self.agents
        snaps = {a: self._snap(self._cars[a].car) for a in agents}
        states = {a: snap.state for a, snap in snaps.items()}
        points = np.array([snap.model_point for snap in snaps.values()])
        wheels = np.vstack([snap.wheel_points for snap in snaps.values()])
        on_road = self.track.contains(wheels).reshape(len(agents), 4)
        any_on, all_on = on_road.any(axis=1).tolist(), on_road.all(axis=1).tolist()
        projection = self._projection_of(agents, points)
        arcs, offsets = projection.arc_length.tolist(), projection.offset.tolist()
        contacts = self._contacts(agents)
        verdicts = {}
        for i, agent in enumerate(agents):
            live = self._cars[agent]
            rec = live.record
            was_frozen = rec.frozen
            moved = math.dist(points[i], live.last_point)
            live.last_point = points[i]
            mine = contacts.get(agent, [])
            status = self._rules.update(
                rec,
                Measurement(
                    arc=arcs[i],
                    moved=moved,
                    any_wheel_on_track=any_on[i],
                    crashed=any(c.at_fault for c in mine),
                ),
                self.time,
            )
            params = build_params(
                track=self.track,
                is_reversed=self.is_reversed,
                model_point=points[i],
                yaw=states[agent].yaw,
                projection=projection,
                index=i,
                progress=self._rules.progress(rec),
                steps=rec.steps,
                speed=live.command[1],
                steering_angle=live.command[0],
                all_wheels_on_track=all_on[i],
                is_offtrack=status == "off_track",
                is_crashed=status == "crashed",
                objects=self._objects_view(exclude=agent),
                waypoints=self._waypoints,
                sim_time=self.time,
            )
            verdicts[agent] = _Verdict(
                params=params,
                contacts=mine,
                status=status,
                offset=offsets[i],
                penalised=not was_frozen and rec.frozen,
                released=was_frozen and not rec.frozen,
            )
        scene = self._scene()
        self._last_offsets = dict(zip(scene.bodies, scene.projection.offset.tolist(), strict=True))
        return verdicts

    def _projection_of(self, agents: list[str], points: np.ndarray) -> Projection:
        """The centre-line projection of the cars' model points, from the scene if it has them."""
        scene = self._scene()
        if all(agent in scene.owners for agent in agents):
            return scene.projection.rows([scene.owners.index(agent) for agent in agents])
        return self.track.project(points)

    def _contacts(self, agents: list[str]) -> dict[str, list[_Contact]]:
        """Every contact of the live cars ``agents`` this step, judged by the fault rules."""
        scene = self._scene()
        pairs = world.contact_pairs(self._client, scene.bodies)
        found: dict[str, list[_Contact]] = {}
        if not pairs:
            return found
        index = {body: i for i, body in enumerate(scene.bodies)}
        for pair in pairs:
            a, b = (index[body] for body in pair)
            for me, other in ((a, b), (b, a)):
                agent = scene.owners[me]
                if agent is None or agent not in agents:
                    continue
                at_fault = self._rules.at_fault(
                    self._party(scene, me, other), self._party(scene, other, me)
                )
                box = scene.bodies[other] if other < len(self._obstacles) else None
                found.setdefault(agent, []).append(_Contact(scene.names[other], at_fault, box))
        for agent_contacts in found.values():
            agent_contacts.sort(key=lambda c: c.other)
        return found

    def _party(self, scene: _Scene, me: int, other: int) -> ContactParty:
        """Scene object ``me`` as a party of its contact with scene object ``other``."""
        if me < len(self._obstacles):
            return ContactParty("box", float(scene.projection.arc_length[me]))
        offsets = scene.projection.offset
        body = scene.bodies[me]
        across = float(offsets[me] - self._last_offsets.get(body, offsets[me]))
        toward = across * float(np.sign(offsets[other] - offsets[me]))
        arc = float(scene.projection.arc_length[me])
        agent = scene.owners[me]
        if agent is None:
            return ContactParty("bot", arc, toward)
        live = self._cars[agent]
        rejoining = live.released_at is not None and self.time - live.released_at <= REJOIN_S + 1e-9
        return ContactParty("car", arc, toward, held=live.hold is not None, rejoining=rejoining)

    def _respawn_and_release(self, verdicts: Mapping[str, _Verdict]) -> None:
        """Respawn the cars penalised this step and release those whose penalty is served;
        both take effect from the next step.

        A penalised car is placed at once, and held there, at the first free spot going
        back from its own (:func:`arena.spawn.respawn_place`); a car whose penalty is
        served is released where it is held if nothing is within ``RESPAWN_CLEARANCE_M``
        of it, else from the first free spot behind. Cars further along the race choose
        first, so the car behind gives way whatever order the cars are listed in.
        """
        moving = [a for a, v in verdicts.items() if v.penalised or v.released]
        if not moving:
            return
        scene = self._scene()
        taken = {
            name: rectangle((box.x, box.y), box.yaw, box.length, box.width)
            for name, box in zip(scene.names, scene.boxes, strict=True)
        }
        moving.sort(key=lambda a: (-self._cars[a].record.distance, self._order.index(a)))
        moved = []
        for agent in moving:
            live, verdict = self._cars[agent], verdicts[agent]
            here = taken.pop(agent)
            others = list(taken.values())
            if verdict.released:
                live.hold, live.released_at = None, self.time
                if is_clear(here, others, RESPAWN_CLEARANCE_M):
                    taken[agent] = here
                    continue
                spot = respawn_place(self.track, live.record.last_arc, verdict.offset, taken=others)
            else:
                spot = self._respawn_place(live, verdict, others)
                live.hold = spot
            live.car.teleport(spot.x, spot.y, spot.yaw)
            self._last_offsets.pop(live.car.body_id, None)
            taken[agent] = car_footprint(spot)
            moved.append(live)
        self._forget_poses()
        for live in moved:
            live.last_point = live.car.model_point()
            self._rules.respawned(live.record, self._arc_of(live.last_point))

    def _respawn_place(self, live: _Live, verdict: _Verdict, taken: list[np.ndarray]) -> Placement:
        """The spot a car penalised this step is held at: behind the box it hit, if any."""
        hit = None
        if verdict.status == "crashed":
            box = next((c.obstacle for c in verdict.contacts if c.obstacle is not None), None)
            if box is not None:
                o = self._obstacle_bodies[box]
                hit = (o.place.arc, o.lane)
        return respawn_place(self.track, live.record.last_arc, verdict.offset, hit, taken)

    def _arc_of(self, point: np.ndarray) -> float:
        return float(self.track.project(point[None, :]).arc_length[0])

    def _park(self, agent: str) -> None:
        live = self._cars[agent]
        if not live.parked:
            index = self.possible_agents.index(agent)
            live.car.teleport(PARK_DISTANCE + 10.0 * index, PARK_DISTANCE, 0.0)
            live.parked = True
            self._forget_poses()

    def restart_car(
        self, agent: str, near: tuple[str, float] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Start a new training episode for one car whose episode ended, others racing on.

        The car comes back at the next training start point (5% further along each time;
        on the centre line, or on the front slot's lane when several cars race) and rejoins
        ``agents``. ``near=(car, gap_m)`` starts it instead ``gap_m`` metres along the track
        from that racing car (negative: behind it), in the other lane: a learner restarted
        behind its opponent has to pass it. Training only: races are never restarted.
        Returns the car's first observation and info.
        """
        if self.config.mode != "training":
            raise RuntimeError("restart_car is for training mode; races run to the end")
        if agent in self.agents:
            raise RuntimeError(f"car {agent!r} is still racing")
        self._car_episodes[agent] += 1
        if near is not None and near[0] in self.agents:
            place = self._beside(near[0], near[1])
        else:
            arc = start_arc(self.config, self.track, self._episode + self._car_episodes[agent])
            if not self.agents:
                self._redraw_obstacles(arc)
            place = grid_slots(len(self.config.cars), self.track, arc)[0]
        self._begin_episode(agent, place)
        observation = self._observe([agent], fresh=True)[agent]
        return observation, self._info(agent, self._initial_params(agent))

    def restart_on_grid(
        self, order: Sequence[str]
    ) -> dict[str, tuple[dict[str, np.ndarray], dict[str, Any]]]:
        """Start new training episodes for ``order``'s cars together, standing on a grid.

        The grid is :func:`~arena.spawn.grid_slots`' at the next training start point, its
        front lane drawn at random; the cars take its slots front first, as a race's start
        puts them. Cars of ``order`` still racing lose their current episode unreported: for
        a caller's frozen opponents, never for a learner mid-episode. The other cars race
        on. Training only. Returns each car's first observation and info.
        """
        if self.config.mode != "training":
            raise RuntimeError("restart_on_grid is for training mode; races run to the end")
        unknown = [a for a in order if a not in self.possible_agents]
        if unknown or len(set(order)) != len(order):
            raise ValueError(f"restart_on_grid needs distinct cars of this race, got {order}")
        for agent in order:
            self._car_episodes[agent] += 1
        episode = self._episode + max(self._car_episodes[a] for a in order)
        front_lane = ("inner", "outer")[int(self.rng.integers(2))]
        arc = start_arc(self.config, self.track, episode)
        slots = grid_slots(len(order), self.track, arc, front_lane)
        for agent, place in zip(order, slots, strict=True):
            self._begin_episode(agent, place)
        observations = self._observe(list(order), fresh=True)
        return {a: (observations[a], self._info(a, self._initial_params(a))) for a in order}

    def _begin_episode(self, agent: str, place: Placement) -> None:
        """Put ``agent`` at ``place``, at rest, on a fresh lap record, and among the racing."""
        live = self._cars[agent]
        live.car.teleport(place.x, place.y, place.yaw)
        live.last_point = live.car.model_point()
        live.record = self._rules.start(self._arc_of(live.last_point), self.time)
        live.hold, live.parked, live.command = None, False, (0.0, 0.0)
        live.released_at = None
        self._last_offsets.pop(live.car.body_id, None)
        self._forget_poses()
        self.agents = [a for a in self.possible_agents if a in self.agents or a == agent]

    def _beside(self, other: str, gap_m: float) -> Placement:
        """The pose ``gap_m`` metres along the track from car ``other``'s origin (the point
        teleport places), in the lane its model point is not in, facing the driving way."""
        snap = self._snap(self._cars[other].car)
        proj = self.track.project(np.array([[snap.state.x, snap.state.y], snap.model_point]))
        arc = float(proj.arc_length[0]) + gap_m
        lane = other_lane(nearest_lane(self.track, arc, float(proj.offset[1])))
        return place_at(self.track, arc, lane)

    def _redraw_obstacles(self, arc0: float) -> None:
        """Random boxes move to a new random layout ahead of ``arc0`` (a lone training car's
        next start), so that a policy learns to see boxes, not where they stood; boxes at
        configured ``positions`` stay where they are."""
        boxes = self.config.obstacles
        if boxes is None or boxes.positions is not None:
            return
        places = obstacle_places(boxes, self.track, arc0, self.rng)
        for obstacle, (place, lane) in zip(self._obstacles, places, strict=True):
            world.move_box(self._client, obstacle.body, place.x, place.y, place.yaw, boxes.size[2])
            obstacle.place, obstacle.lane = place, lane

    # ------------------------------------------------------------ observations
    def _snap(self, car: Car) -> CarSnapshot:
        """The car's pose and points now, read from PyBullet once per step."""
        snap = self._snaps.get(car.body_id)
        if snap is None:
            snap = self._snaps[car.body_id] = car.snapshot()
        return snap

    def _forget_poses(self) -> None:
        """Drop the per-step caches (after physics ran or a car was moved)."""
        self._snaps.clear()
        self._scene_cache = None

    def _scene(self) -> _Scene:
        """Every object on track now (obstacles, bots, racing cars), computed once a step."""
        if self._scene_cache is not None:
            return self._scene_cache
        owners: list[str | None] = []
        names, bodies = [], []
        locations, headings, speeds, boxes = [], [], [], []
        for i, o in enumerate(self._obstacles):
            owners.append(None)
            names.append(f"box{i}")
            bodies.append(o.body)
            locations.append((o.place.x, o.place.y))
            headings.append(0.0)  # DeepRacer reports 0 for a static obstacle's heading
            speeds.append(0.0)
            boxes.append(Box3D(o.place.x, o.place.y, o.place.yaw, *o.size, gray=BOX_GRAY))
        movers = [(None, f"bot{i}", b.car, BOT_GRAY) for i, b in enumerate(self._bots)] + [
            (a, a, self._cars[a].car, CAR_GRAY) for a in self._order if not self._cars[a].parked
        ]
        for owner, name, car, gray in movers:
            snap = self._snap(car)
            state = snap.state
            owners.append(owner)
            names.append(name)
            bodies.append(car.body_id)
            locations.append(snap.model_point)
            headings.append(math.degrees(state.yaw))
            speeds.append(abs(state.speed))
            cx, cy = snap.centre
            spec = car.spec
            boxes.append(Box3D(cx, cy, state.yaw, spec.length, spec.width, spec.height, gray))
        loc = np.array(locations, dtype=float).reshape(-1, 2)
        heading = (np.array(headings) + 180.0) % 360.0 - 180.0
        projection = self.track.project(loc)
        view = ObjectsView.of(loc, heading, np.array(speeds), projection)
        targets = np.array(
            [(b.x, b.y, 0.5 * math.hypot(b.length, b.width) + LIDAR_CULL_MARGIN) for b in boxes]
        ).reshape(-1, 3)
        self._scene_cache = _Scene(view, projection, boxes, owners, names, bodies, targets)
        return self._scene_cache

    def _objects_view(self, exclude: str) -> ObjectsView:
        """Obstacles, bots and the other cars still racing, as DeepRacer's object keys see them."""
        scene = self._scene()
        if exclude not in scene.owners:
            return scene.objects
        return scene.objects.without(scene.owners.index(exclude))

    def _boxes(self, exclude: str) -> list[Box3D]:
        scene = self._scene()
        return [
            box for box, owner in zip(scene.boxes, scene.owners, strict=True) if owner != exclude
        ]

    def _observe(
        self, agents: list[str] | None = None, fresh: bool = False
    ) -> dict[str, dict[str, np.ndarray]]:
        """Every sensor of ``agents`` (default: the live cars); lidars scan in one batch.

        Cars that stack frames get their last ``stack_size`` frames; ``fresh`` (an episode
        start) fills their stacks with copies of this first frame.
        """
        agents = self.agents if agents is None else agents
        with_lidar = [a for a in agents if a in self._lidar_reach]
        ranges = self._scan_lidars(with_lidar) if with_lidar else {}
        observations = {agent: self._observe_one(agent, ranges.get(agent)) for agent in agents}
        if self._stack_sizes:
            for agent in self._stack_sizes.keys() & observations.keys():
                observations[agent] = self._stack(agent, observations[agent], fresh)
        return observations

    def _stack(
        self, agent: str, frame: dict[str, np.ndarray], fresh: bool
    ) -> dict[str, np.ndarray]:
        """A stacking car's observation: its stack without the oldest frame, plus ``frame``.

        New arrays every step (earlier observations handed out stay as they were).
        """
        k = self._stack_sizes[agent]
        last = None if fresh else self._stacks.get(agent)
        if last is None:
            stacked = {n: np.concatenate([f] * k, axis=-1) for n, f in frame.items()}
        else:
            stacked = {
                n: np.concatenate([last[n][..., f.shape[-1] :], f], axis=-1)
                for n, f in frame.items()
            }
        self._stacks[agent] = stacked
        return stacked

    def _scan_lidars(self, agents: list[str]) -> dict[str, np.ndarray]:
        """Lidar ranges of ``agents``, casting only beams aimed at objects they could see.

        The cars scan (and draw their noise) front to back on the grid, whatever order
        ``agents`` lists them in.
        """
        scene = self._scene()
        agents = sorted(agents, key=self._order.index)
        poses, excludes = [], []
        for agent in agents:
            car = self._cars[agent].car
            state = self._snap(car).state
            poses.append((state.x, state.y, state.yaw))
            excludes.append((car.body_id,))
        visible = [[owner != agent for owner in scene.owners] for agent in agents]
        scans = self._lidar.scan_many(
            np.array(poses),
            excludes,
            rng=self.rng,
            reach=[self._lidar_reach[agent] for agent in agents],
            targets=scene.targets,
            visible=np.array(visible, dtype=bool).reshape(len(agents), len(scene.owners)),
        )
        return dict(zip(agents, scans, strict=True))

    def _observe_one(self, agent: str, ranges: np.ndarray | None) -> dict[str, np.ndarray]:
        """One car's observation; ``ranges`` is its lidar scan if it has a lidar."""
        car = self._cars[agent].car
        state = self._snap(car).state
        sensors = self._car_configs[agent].sensors
        lidar_cfg = self._car_configs[agent].lidar_config
        obs: dict[str, np.ndarray] = {}
        if ranges is not None:
            angles = self._lidar.beam_angles
            if "lidar" in sensors:
                obs["lidar"] = clip_lidar(ranges)
            if "sector_lidar" in sensors:
                obs["sector_lidar"] = sector_lidar(
                    ranges, angles, num_sectors=lidar_cfg.num_sectors
                )
            if "discretized_sector_lidar" in sensors:
                obs["discretized_sector_lidar"] = discretized_sector_lidar(
                    ranges,
                    angles,
                    num_sectors=lidar_cfg.num_sectors,
                    num_values=lidar_cfg.num_values_per_sector,
                    clip=lidar_cfg.clipping_dist,
                )
        if self._camera is not None and ("camera" in sensors or "stereo" in sensors):
            boxes = self._boxes(exclude=agent)
            if "camera" in sensors:
                obs["camera"] = self._camera.render(state.x, state.y, state.yaw, boxes)[..., None]
            else:
                obs["stereo"] = self._camera.render_stereo(state.x, state.y, state.yaw, boxes)
        return {name: obs[name] for name in self._obs_spaces[agent].spaces}

    def _initial_params(self, agent: str) -> dict[str, Any]:
        snap = self._snap(self._cars[agent].car)
        projection = self.track.project(snap.model_point[None, :])
        wheels_on = self.track.contains(snap.wheel_points)
        return build_params(
            track=self.track,
            is_reversed=self.is_reversed,
            model_point=snap.model_point,
            yaw=snap.state.yaw,
            projection=projection,
            index=0,
            progress=0.0,
            steps=0,
            speed=0.0,
            steering_angle=0.0,
            all_wheels_on_track=bool(wheels_on.all()),
            is_offtrack=False,
            is_crashed=False,
            objects=self._objects_view(exclude=agent),
            waypoints=self._waypoints,
            sim_time=self.time,
        )

    def _info(
        self, agent: str, params: dict[str, Any], contacts: Sequence[_Contact] = ()
    ) -> dict[str, Any]:
        """A car's step info: its params and record, its race ``distance`` (m since its
        start) and its ``contacts`` this step (``other``: a car's name, ``bot<i>`` or
        ``box<i>``; ``at_fault``: whether this car caused it)."""
        rec = self._cars[agent].record
        return {
            "params": params,
            "distance": rec.distance,
            "contacts": [{"other": c.other, "at_fault": c.at_fault} for c in contacts],
            "episode_status": rec.status,
            "laps": rec.laps,
            "lap_times": list(rec.lap_times),
            "off_track_count": rec.off_track_count,
            "crash_count": rec.crash_count,
            "reset_count": rec.reset_count,
            "penalty_seconds": rec.penalty_seconds,
            "pause_left": rec.frozen_until - self.time if rec.frozen_until is not None else 0.0,
            "done": rec.done,
            "progress": self._rules.progress(rec),
            "time": self.time,
        }

    # ----------------------------------------------------------- rendering etc
    def retire(self, agent: str) -> None:
        """End ``agent``'s race now, as a DNF (neither finished nor out of time): it drives
        this control step and is then parked off the track, as any car whose race is over."""
        self._cars[agent].record.done = True

    def record(self, agent: str) -> CarRecord:
        """A car's racing record: laps, lap times, incidents, penalties."""
        return self._cars[agent].record

    def car_poses(self) -> dict[str, tuple[float, float, float, float]]:
        """``(x, y, yaw, speed)`` of every controlled car (parked ones included)."""
        out = {}
        for agent, live in self._cars.items():
            s = live.car.state()
            out[agent] = (s.x, s.y, s.yaw, s.speed)
        return out

    def bot_poses(self) -> list[tuple[float, float, float]]:
        """``(x, y, yaw)`` of every bot car."""
        return [(s.x, s.y, s.yaw) for s in (b.car.state() for b in self._bots)]

    def obstacle_poses(self) -> list[tuple[float, float, float, float, float]]:
        """``(x, y, yaw, length, width)`` of every obstacle box."""
        return [(o.place.x, o.place.y, o.place.yaw, o.size[0], o.size[1]) for o in self._obstacles]

    def render(self) -> np.ndarray | None:
        """A top-down RGB picture of the race (``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array":
            return None
        from arena.render import TopDownRenderer

        if self._renderer is None:
            self._renderer = TopDownRenderer(self.track)
        return self._renderer.frame(
            cars=[
                (pose, CAR_COLORS[i])
                for i, pose in enumerate(self.car_poses().values())
                if not self._cars[self.possible_agents[i]].parked
            ],
            bots=self.bot_poses(),
            obstacles=self.obstacle_poses(),
        )

    def close(self) -> None:
        """Disconnect the physics client."""
        if self._client is not None:
            world.close(self._client)
            self._client = None
