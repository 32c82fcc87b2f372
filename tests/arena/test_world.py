"""Tests of the arena's physics world: stepping, boxes, contacts, collisions."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pybullet as p
import pytest

from arena.car import SOLID_MASK, Car
from arena.world import (
    PhysicsSettings,
    add_box,
    close,
    contact_pairs,
    create_world,
    physics_cost,
    step,
    substeps,
)

SETTINGS = PhysicsSettings()


@pytest.fixture
def client() -> Iterator[int]:
    cid = create_world(SETTINGS)
    yield cid
    close(cid)


def test_substeps() -> None:
    assert substeps(PhysicsSettings(physics_hz=60.0)) == 4
    assert substeps(PhysicsSettings(physics_hz=240.0)) == 16
    assert substeps(PhysicsSettings(physics_hz=10.0)) == 1


def test_step_advances_one_control_period(client: int) -> None:
    ball = p.createMultiBody(
        1.0,
        p.createCollisionShape(p.GEOM_SPHERE, radius=0.05, physicsClientId=client),
        basePosition=[0, 0, 10],
        physicsClientId=client,
    )
    step(client, SETTINGS)
    (_, _, vz), _ = p.getBaseVelocity(ball, physicsClientId=client)
    assert vz == pytest.approx(-9.81 / SETTINGS.control_hz, rel=0.01)  # base damping 0.04/s


def test_box_stands_on_the_ground(client: int) -> None:
    box = add_box(client, 1.0, 2.0, math.pi / 2, size=(0.4, 0.5, 0.3))
    lo, hi = p.getAABB(box, physicsClientId=client)
    np.testing.assert_allclose(lo, [0.75, 1.8, 0.0], atol=1e-3)
    np.testing.assert_allclose(hi, [1.25, 2.2, 0.3], atol=1e-3)
    step(client, SETTINGS)
    pos, _ = p.getBasePositionAndOrientation(box, physicsClientId=client)
    assert pos == pytest.approx((1.0, 2.0, 0.15))


def test_head_on_cars_do_not_pass_through(client: int) -> None:
    a = Car(client, x=-5.0, yaw=0.0)
    b = Car(client, x=5.0, yaw=math.pi)
    touched = False
    worst_gap = math.inf
    for _ in range(75):
        a.apply_command(0.0, 4.0)
        b.apply_command(0.0, 4.0)
        step(client, SETTINGS)
        touched |= (min(a.body_id, b.body_id), max(a.body_id, b.body_id)) in contact_pairs(
            client, [a.body_id, b.body_id]
        )
        worst_gap = min(worst_gap, b.footprint()[:, 0].min() - a.footprint()[:, 0].max())
    assert touched
    assert worst_gap > -0.15  # some overlap during the 8 m/s impact, never through
    final_gap = b.footprint()[:, 0].min() - a.footprint()[:, 0].max()
    assert -0.02 < final_gap < 0.05  # pushing against each other, nose to nose
    assert a.state().x < b.state().x


def test_car_stops_at_a_box(client: int) -> None:
    car = Car(client)
    box = add_box(client, 2.0, 0.0, 0.0)  # near face at x = 1.8
    for _ in range(60):
        car.apply_command(0.0, 4.0)
        step(client, SETTINGS)
        assert car.footprint()[:, 0].max() < 1.9
    assert car.footprint()[:, 0].max() == pytest.approx(1.8, abs=0.02)
    assert abs(car.state().speed) < 0.05
    assert contact_pairs(client, [box, car.body_id]) == {
        (min(box, car.body_id), max(box, car.body_id))
    }


def test_contact_pairs_ignore_distant_bodies_and_ground(client: int) -> None:
    cars = [Car(client, x=0.0, y=1.0 * i) for i in range(3)]
    box = add_box(client, 3.0, 0.0, 0.0)
    step(client, SETTINGS)
    assert contact_pairs(client, [c.body_id for c in cars] + [box]) == set()


def _connected_clients() -> set[int]:
    return {cid for cid in range(64) if p.getConnectionInfo(cid)["isConnected"]}


def test_physics_cost_returns_a_duration_and_closes_its_world() -> None:
    """How long a step takes is measured by ``benchmarks/env_throughput.py`` (physics floor)."""
    before = _connected_clients()
    cost = physics_cost(2, SETTINGS, steps=5)
    assert isinstance(cost, float) and math.isfinite(cost) and cost > 0.0
    assert _connected_clients() == before


def test_close_disconnects() -> None:
    cid = create_world(SETTINGS)
    close(cid)
    assert p.getConnectionInfo(cid)["isConnected"] == 0


def test_rays_see_boxes_and_chassis_but_not_wheels_or_own_body(client: int) -> None:
    car = Car(client)
    box = add_box(client, 1.5, 0.0, 0.0)  # near face at x = 1.3

    def first_hit(start: list[float], end: list[float]) -> tuple[int, tuple[float, ...]]:
        hit = p.rayTestBatch([start], [end], collisionFilterMask=SOLID_MASK, physicsClientId=client)
        return hit[0][0], hit[0][3]

    body, point = first_hit([0.14, 0.0, 0.1], [3.0, 0.0, 0.1])  # from inside the chassis
    assert body == box and point[0] == pytest.approx(1.3)
    body, point = first_hit([0.0, 1.0, 0.03], [0.0, -1.0, 0.03])  # wheel sticks out further
    assert body == car.body_id and point[1] == pytest.approx(car.spec.width / 2)
    assert first_hit([3.0, 3.0, 1.0], [3.0, 3.0, -1.0])[0] == -1  # ground skipped
