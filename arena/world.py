"""The physics world of the arena: one PyBullet DIRECT client per env.

Settings
--------
* Control at 15 Hz; physics at 60 Hz (4 steps per control step) with 10 solver
  iterations, the cheapest setting that passes every sanity test in
  ``tests/arena/test_car.py`` and ``test_world.py`` cleanly. Measured on the 2-core
  development machine with ``physics_cost``: about 0.15 ms per control step for one
  car and 0.56 ms for four (design.md's first-try car: 1.9 ms for four at 120 Hz),
  under 30% of the 2 ms budget of a 4-car control step.
* Rejected: 30 and 45 Hz (cars closing head-on at 8 m/s overlap so deeply within one
  step that they pass through each other or climb); 120 Hz (twice the cost, no test
  needed it); 5 iterations (cars drift off a straight line and wobble in turns); 15-20
  iterations (about 10-20% dearer, slightly tighter circles, not needed).
* Gravity 9.81 m/s^2; a static ground plane with friction 1.0 (the tyre/road friction is
  then the wheels' 0.5, Bullet multiplying the two); no restitution anywhere.
* Collision groups (see ``arena.car``): obstacle boxes touch cars' chassis and bodies
  with default filters, never wheels; ray tests see them.
* Determinism: deterministic overlapping pairs, a fixed time step and no real-time
  simulation, so the same calls in a fresh client give bit-identical states.
* Reuse: an env builds each episode's world in the client of the one before, emptied by
  PyBullet's ``resetSimulation`` (which deletes and recreates its dynamics world, body
  ids from 0 again), so its states are bit-identical to a fresh client's. A new
  connection costs about 25 ms, the time of 30-100 control steps, which a loop that
  resets after every short episode paid each time (benchmarks/RESULTS.md, "Worlds reused
  across resets").
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import pybullet as p

from arena.car import ALL_GROUPS, GROUND_GROUP, OBSTACLE_GROUP, SOLID_MASK, Car

GRAVITY = 9.81
GROUND_FRICTION = 1.0
BOX_COLOR = (0.9, 0.6, 0.1, 1.0)


@dataclass(frozen=True)
class PhysicsSettings:
    """Control and physics rates (Hz) and solver iterations."""

    control_hz: float = 15.0
    physics_hz: float = 60.0
    solver_iterations: int = 10


def substeps(settings: PhysicsSettings) -> int:
    """Physics steps per control step."""
    return max(1, round(settings.physics_hz / settings.control_hz))


def create_world(settings: PhysicsSettings = PhysicsSettings(), client: int | None = None) -> int:
    """A world with gravity, the ground plane and fixed steps; return its client id.

    Connects a DIRECT client, or empties ``client`` (every body and setting gone) and
    builds the world there.
    """
    if client is None:
        client = p.connect(p.DIRECT)
    else:
        p.resetSimulation(physicsClientId=client)
    p.setGravity(0.0, 0.0, -GRAVITY, physicsClientId=client)
    p.setPhysicsEngineParameter(
        fixedTimeStep=1.0 / (settings.control_hz * substeps(settings)),
        numSolverIterations=settings.solver_iterations,
        numSubSteps=0,
        deterministicOverlappingPairs=1,
        physicsClientId=client,
    )
    p.setRealTimeSimulation(0, physicsClientId=client)
    plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client)
    ground = p.createMultiBody(0.0, plane, physicsClientId=client)
    p.setCollisionFilterGroupMask(
        ground, -1, GROUND_GROUP, ALL_GROUPS ^ OBSTACLE_GROUP, physicsClientId=client
    )
    p.changeDynamics(ground, -1, lateralFriction=GROUND_FRICTION, physicsClientId=client)
    return client


def step(client: int, settings: PhysicsSettings) -> None:
    """Advance physics by one control period."""
    for _ in range(substeps(settings)):
        p.stepSimulation(physicsClientId=client)


def add_box(
    client: int,
    x: float,
    y: float,
    yaw: float,
    size: tuple[float, float, float] = (0.4, 0.5, 0.3),
    color: tuple[float, float, float, float] = BOX_COLOR,
) -> int:
    """Add a static box standing on the ground; ``size`` = (length along yaw, width, height)."""
    half = [size[0] / 2.0, size[1] / 2.0, size[2] / 2.0]
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
    vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=color, physicsClientId=client)
    body = p.createMultiBody(0.0, col, vis, *_standing(x, y, yaw, size[2]), physicsClientId=client)
    p.setCollisionFilterGroupMask(body, -1, OBSTACLE_GROUP, SOLID_MASK, physicsClientId=client)
    return body


def move_box(client: int, body: int, x: float, y: float, yaw: float, height: float) -> None:
    """Stand a box made by :func:`add_box` (``height`` tall) at ``(x, y)`` facing ``yaw``."""
    p.resetBasePositionAndOrientation(body, *_standing(x, y, yaw, height), physicsClientId=client)


def _standing(x: float, y: float, yaw: float, height: float) -> tuple[list[float], tuple]:
    """Base position and orientation of a box ``height`` tall standing at ``(x, y)``."""
    return [x, y, height / 2.0], p.getQuaternionFromEuler([0.0, 0.0, yaw])


def contact_pairs(
    client: int, bodies: Sequence[int], margin: float = 0.005
) -> set[tuple[int, int]]:
    """Pairs (a < b) of ``bodies`` whose shapes are within ``margin`` m after the last step."""
    pairs = set()
    for a, b in itertools.combinations(sorted(bodies), 2):
        points = p.getContactPoints(a, b, physicsClientId=client)
        if any(pt[8] <= margin for pt in points):
            pairs.add((a, b))
    return pairs


def close(client: int) -> None:
    """Disconnect the client."""
    p.disconnect(physicsClientId=client)


def physics_cost(
    num_cars: int, settings: PhysicsSettings = PhysicsSettings(), steps: int = 300
) -> float:
    """Seconds of wall time per control step for ``num_cars`` cars driving circles."""
    client = create_world(settings)
    try:
        cars = [Car(client, x=0.0, y=2.0 * i) for i in range(num_cars)]
        commands = [(20.0 * math.sin(0.05 * t), 2.0 + math.sin(0.03 * t)) for t in range(steps)]
        start = time.perf_counter()
        for steering, speed in commands:
            for car in cars:
                car.apply_command(steering, speed)
            step(client, settings)
        return (time.perf_counter() - start) / steps
    finally:
        close(client)
