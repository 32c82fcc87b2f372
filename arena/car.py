"""The 1/18 scale car: a PyBullet multibody built in code (no URDF).

Its dimensions and limits come from :class:`arena.car_spec.CarSpec`; the figures below
are that spec's defaults.

Frames and geometry
-------------------
* The **car origin** is the centre of the rear axle on the ground. ``CarState`` x, y,
  speed and velocities describe that point; the DeepRacer "model point" lies
  ``model_point_ahead`` (0.14 m) further along the heading, between the axles.
* Turning geometry follows from this choice: at steering angle ``d`` the origin drives a
  circle of radius ``wheelbase / tan(d)`` (0.284 m at full lock; measured 0.291 m at
  1 m/s, the tyres slipping a little).
* The collision footprint (``length`` x ``width`` = 0.3235 x 0.196 m) is centred on the
  middle of the wheelbase, so it reaches 0.080 m behind the rear axle and 0.080 m past
  the front axle. ``wheel_points`` and ``footprint`` use the yaw only (the track is flat).

Construction: 6 links and 6 revolute joints, the fewest that give two steering hinges
and four driven wheels
-------------------------------------------------------------------------------------
* Base: the chassis, mass ``chassis_mass`` (5 kg), centre of mass at mid-wheelbase 0.06 m
  above the ground. Its collision box has the footprint's size and ``height`` 0.16 m,
  from 0.02 m to 0.18 m above the ground (about the real car with its sensor mast). The
  height matters: two cars closing at 8 m/s overlap by up to 0.13 m within one 60 Hz
  step, and a box shallower than that gets pushed apart vertically (cars climbed over
  each other with a 0.08 m box).
* Two steering knuckles (revolute about the vertical, no collision shape, 0.1 kg) carry
  the front wheels; the rear wheels hang directly on the chassis.
* Wheels are **spheres** of ``rolling_radius``, ``wheel_mass`` 0.34 kg each (simapp's
  masses: 6.56 kg in all), on revolute joints about the car's lateral axis. A sphere
  touches a flat floor at one point whatever its spin, so it rolls like a cylinder here,
  is the cheapest contact Bullet has and stays correct at a coarse step.
* Collision filtering: wheels touch only the ground; the chassis touches everything
  (ground, other cars, obstacle boxes, bodies added with default filters). A car's own
  links never collide with each other. Ray tests (lidar) never hit wheels; with
  ``collisionFilterMask=SOLID_MASK`` they skip the ground too. A ray that starts inside a
  chassis box leaves it without a hit, so a car's lidar does not see its own body.

Drivetrain and steering (DeepRacer's, from deepracer-simapp; sources in ``arena.car_spec``)
-----------------------------------------------------------------------------------------
* Friction: ``wheel_friction`` 0.5 on the wheels, 1.0 on the ground; Bullet multiplies
  the two, so the tyre/road coefficient is the rules' 0.5 (at most 4.9 m/s^2).
* ``apply_command`` clips steering to +/-30 deg and speed to [0.1, 4.0] m/s, as simapp
  does. Every wheel is a velocity motor of ``wheel_torque`` (10 N m) whose target spin is
  the same on all four: speed / ``wheel_radius`` (0.035 m), clipped to ``max_wheel_spin``
  (100 rad/s). The spheres roll at ``rolling_radius`` (0.036 m), so a command of v
  drives about 1.03 v and every command from 3.5 m/s up drives the top speed, 3.6 m/s.
  The torque is far above what the tyres can pass to the road: drive and braking are
  grip-limited, about 0.5 g both ways. There is no differential: in a bend the four
  wheels spin alike and scrub, as simapp's do.
* Both front knuckles get the commanded angle (no Ackermann) through position motors of
  ``steering_torque`` whose gain closes ``physics step / steering_time_constant`` of the
  gap each physics step: a first-order lag of 0.5 s, simapp's position PID (p 1.0,
  d 0.5) on its near-massless hinge.
* ``stop`` zeroes every velocity and sets the wheel motors to hold zero spin, so a frozen
  car stays put while physics runs on, until its next ``apply_command``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet as p

from arena.car_spec import DEFAULT_CAR, CarSpec

# Collision groups (bits above PyBullet's defaults 1 and 2, which other bodies keep).
GROUND_GROUP = 1 << 4
CAR_GROUP = 1 << 5  # chassis
OBSTACLE_GROUP = 1 << 6
WHEEL_GROUP = 1 << 7
ALL_GROUPS = -1
# Collision mask of obstacles, and a ray mask (``rayTestBatch(collisionFilterMask=...)``):
# chassis, boxes and other solid bodies, not the ground or the wheels.
SOLID_MASK = ALL_GROUPS ^ GROUND_GROUP ^ WHEEL_GROUP

_KNUCKLE_INERTIA = 1e-5
_CHASSIS_CLEARANCE = 0.02
_COM_HEIGHT = 0.06
_WHEEL_COLOR = (0.1, 0.1, 0.1, 1.0)

# Link indices, fixed by the construction order in ``Car._build``.
_FL_STEER, _FL_WHEEL, _FR_STEER, _FR_WHEEL, _RL_WHEEL, _RR_WHEEL = range(6)
_STEER_JOINTS = [_FL_STEER, _FR_STEER]
_WHEEL_JOINTS = [_FL_WHEEL, _FR_WHEEL, _RL_WHEEL, _RR_WHEEL]


@dataclass(frozen=True)
class CarState:
    """Pose and motion of the car origin (rear-axle centre) in the world frame.

    ``yaw`` is in radians (0 = +x, counter-clockwise positive); ``speed`` is the signed
    speed along the heading; ``vx``, ``vy`` the world-frame velocity; ``yaw_rate`` rad/s.
    """

    x: float
    y: float
    yaw: float
    speed: float
    vx: float
    vy: float
    yaw_rate: float


@dataclass(frozen=True)
class CarSnapshot:
    """Everything the rules and sensors read from a car at one instant."""

    state: CarState
    model_point: np.ndarray
    wheel_points: np.ndarray
    centre: tuple[float, float]  # of the chassis footprint (the centre of mass)


def _yaw_of(quat: tuple[float, float, float, float]) -> float:
    qx, qy, qz, qw = quat
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def _corners(length: float, width: float) -> np.ndarray:
    half_l, half_w = length / 2.0, width / 2.0
    return np.array([[half_l, half_w], [-half_l, half_w], [-half_l, -half_w], [half_l, -half_w]])


class Car:
    """One car in a PyBullet client; see the module docstring for the model."""

    def __init__(
        self,
        client: int,
        spec: CarSpec = DEFAULT_CAR,
        x: float = 0.0,
        y: float = 0.0,
        yaw: float = 0.0,
        color: tuple[float, float, float, float] = (0.8, 0.1, 0.1, 1.0),
    ) -> None:
        self.client = client
        self.spec = spec
        # The base frame is the chassis centre of mass, mid-wheelbase.
        self._com_ahead = spec.centre_ahead
        half_wb, half_tr = spec.wheelbase / 2.0, spec.track / 2.0
        self._wheel_offsets = np.array(
            [[half_wb, half_tr], [half_wb, -half_tr], [-half_wb, half_tr], [-half_wb, -half_tr]]
        )
        self._footprint = _corners(spec.length, spec.width)
        # Model point and wheels in the base frame, for snapshot().
        self._snapshot_points = np.vstack(
            [[spec.model_point_ahead - self._com_ahead, 0.0], self._wheel_offsets]
        )
        # Bullet's position motor closes this share of the gap each physics step.
        step = p.getPhysicsEngineParameters(physicsClientId=client)["fixedTimeStep"]
        self._steering_gain = min(1.0, step / spec.steering_time_constant)
        self.body_id = self._build(color)
        self.teleport(x, y, yaw)

    def _build(self, color: tuple[float, float, float, float]) -> int:
        s, c = self.spec, self.client
        half = [s.length / 2.0, s.width / 2.0, s.height / 2.0]
        # The box hangs off the centre of mass: it reaches higher than the mass does.
        lift = [0.0, 0.0, _CHASSIS_CLEARANCE + half[2] - _COM_HEIGHT]
        chassis_col = p.createCollisionShape(
            p.GEOM_BOX, halfExtents=half, collisionFramePosition=lift, physicsClientId=c
        )
        chassis_vis = p.createVisualShape(
            p.GEOM_BOX,
            halfExtents=half,
            visualFramePosition=lift,
            rgbaColor=color,
            physicsClientId=c,
        )
        wheel_col = p.createCollisionShape(
            p.GEOM_SPHERE, radius=s.rolling_radius, physicsClientId=c
        )
        wheel_vis = p.createVisualShape(
            p.GEOM_SPHERE, radius=s.rolling_radius, rgbaColor=_WHEEL_COLOR, physicsClientId=c
        )
        axle_z = s.rolling_radius - _COM_HEIGHT
        half_wb, half_tr = s.wheelbase / 2.0, s.track / 2.0
        front_left, front_right = [half_wb, half_tr, axle_z], [half_wb, -half_tr, axle_z]
        rear_left, rear_right = [-half_wb, half_tr, axle_z], [-half_wb, -half_tr, axle_z]
        origin = [0.0, 0.0, 0.0]
        # Knuckle, wheel on knuckle (x2), then rear wheels on the chassis.
        masses = [s.knuckle_mass, s.wheel_mass] * 2 + [s.wheel_mass] * 2
        cols = [-1, wheel_col, -1, wheel_col, wheel_col, wheel_col]
        vis = [-1, wheel_vis, -1, wheel_vis, wheel_vis, wheel_vis]
        positions = [front_left, origin, front_right, origin, rear_left, rear_right]
        parents = [0, 1, 0, 3, 0, 0]
        axes = [[0, 0, 1], [0, 1, 0], [0, 0, 1], [0, 1, 0], [0, 1, 0], [0, 1, 0]]
        n = len(masses)
        body = p.createMultiBody(
            baseMass=s.chassis_mass,
            baseCollisionShapeIndex=chassis_col,
            baseVisualShapeIndex=chassis_vis,
            basePosition=[0.0, 0.0, _COM_HEIGHT],
            linkMasses=masses,
            linkCollisionShapeIndices=cols,
            linkVisualShapeIndices=vis,
            linkPositions=positions,
            linkOrientations=[[0, 0, 0, 1]] * n,
            linkInertialFramePositions=[origin] * n,
            linkInertialFrameOrientations=[[0, 0, 0, 1]] * n,
            linkParentIndices=parents,
            linkJointTypes=[p.JOINT_REVOLUTE] * n,
            linkJointAxis=axes,
            physicsClientId=c,
        )
        p.setCollisionFilterGroupMask(body, -1, CAR_GROUP, ALL_GROUPS, physicsClientId=c)
        for link in _STEER_JOINTS:
            p.setCollisionFilterGroupMask(body, link, 0, 0, physicsClientId=c)
            p.changeDynamics(
                body, link, localInertiaDiagonal=[_KNUCKLE_INERTIA] * 3, physicsClientId=c
            )
        for link in _WHEEL_JOINTS:
            p.setCollisionFilterGroupMask(body, link, WHEEL_GROUP, GROUND_GROUP, physicsClientId=c)
            p.changeDynamics(
                body,
                link,
                lateralFriction=s.wheel_friction,
                linearDamping=0.0,
                angularDamping=0.0,
                physicsClientId=c,
            )
        p.changeDynamics(body, -1, linearDamping=0.0, angularDamping=0.0, physicsClientId=c)
        return body

    def apply_command(self, steering_deg: float, speed: float) -> None:
        """Set steering (deg, positive = left) and target speed (m/s), clipped to limits."""
        s = self.spec
        steer = math.radians(min(max(float(steering_deg), -s.max_steering_deg), s.max_steering_deg))
        self._set_motors(steer, s.wheel_spin(speed))

    def _set_motors(self, steer: float, spin: float) -> None:
        s, c = self.spec, self.client
        p.setJointMotorControlArray(
            self.body_id,
            _STEER_JOINTS,
            p.POSITION_CONTROL,
            targetPositions=[steer, steer],
            forces=[s.steering_torque] * 2,
            positionGains=[self._steering_gain] * 2,
            physicsClientId=c,
        )
        p.setJointMotorControlArray(
            self.body_id,
            _WHEEL_JOINTS,
            p.VELOCITY_CONTROL,
            targetVelocities=[spin] * 4,
            forces=[s.wheel_torque] * 4,
            physicsClientId=c,
        )

    def _base(self) -> tuple[float, float, float]:
        pos, quat = p.getBasePositionAndOrientation(self.body_id, physicsClientId=self.client)
        return pos[0], pos[1], _yaw_of(quat)

    def state(self) -> CarState:
        """Current pose and motion of the car origin."""
        cx, cy, yaw = self._base()
        (vx, vy, _), (_, _, wz) = p.getBaseVelocity(self.body_id, physicsClientId=self.client)
        cos, sin = math.cos(yaw), math.sin(yaw)
        # The origin is com_ahead behind the centre of mass: v_o = v_com + w x r.
        ox, oy = -self._com_ahead * cos, -self._com_ahead * sin
        vx, vy = vx - wz * oy, vy + wz * ox
        return CarState(cx + ox, cy + oy, yaw, vx * cos + vy * sin, vx, vy, wz)

    def snapshot(self) -> CarSnapshot:
        """State, model point, wheel points and footprint centre from one pose query."""
        cx, cy, yaw = self._base()
        (vx, vy, _), (_, _, wz) = p.getBaseVelocity(self.body_id, physicsClientId=self.client)
        cos, sin = math.cos(yaw), math.sin(yaw)
        ox, oy = -self._com_ahead * cos, -self._com_ahead * sin
        vx, vy = vx - wz * oy, vy + wz * ox
        state = CarState(cx + ox, cy + oy, yaw, vx * cos + vy * sin, vx, vy, wz)
        rotation = np.array([[cos, sin], [-sin, cos]])
        world = self._snapshot_points @ rotation + (cx, cy)
        return CarSnapshot(state, world[0], world[1:5], (cx, cy))

    def _to_world(self, local: np.ndarray) -> np.ndarray:
        cx, cy, yaw = self._base()
        cos, sin = math.cos(yaw), math.sin(yaw)
        return local @ np.array([[cos, sin], [-sin, cos]]) + (cx, cy)

    def model_point(self) -> np.ndarray:
        """The DeepRacer model point (world x, y), ``model_point_ahead`` ahead of the origin."""
        return self._to_world(np.array([self.spec.model_point_ahead - self._com_ahead, 0.0]))

    def wheel_points(self) -> np.ndarray:
        """Ground contact points of the wheels (FL, FR, RL, RR) as a (4, 2) world array."""
        return self._to_world(self._wheel_offsets)

    def footprint(self) -> np.ndarray:
        """Corners of the collision footprint, counter-clockwise from front-left, (4, 2)."""
        return self._to_world(self._footprint)

    def teleport(self, x: float, y: float, yaw: float) -> None:
        """Place the car origin at (x, y) facing ``yaw`` rad, at rest with wheels straight."""
        self._place_base(x, y, yaw)
        for joint in range(len(_STEER_JOINTS) + len(_WHEEL_JOINTS)):
            p.resetJointState(self.body_id, joint, 0.0, 0.0, physicsClientId=self.client)
        self.stop()

    def hold(self, x: float, y: float, yaw: float) -> None:
        """Put a car that was :meth:`teleport`-ed to ``(x, y, yaw)`` back there, at rest.

        Cheaper than ``teleport`` for a car held in place step after step: only the base
        is reset; the wheels were stopped when it was first placed.
        """
        self._place_base(x, y, yaw)
        p.resetBaseVelocity(
            self.body_id, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=self.client
        )

    def _place_base(self, x: float, y: float, yaw: float) -> None:
        """Put the base so that the car origin is at ``(x, y)``, facing ``yaw``."""
        com = [x + self._com_ahead * math.cos(yaw), y + self._com_ahead * math.sin(yaw)]
        quat = p.getQuaternionFromEuler([0.0, 0.0, yaw])
        p.resetBasePositionAndOrientation(
            self.body_id, [*com, _COM_HEIGHT], quat, physicsClientId=self.client
        )

    def stop(self) -> None:
        """Zero all velocities in place and hold the wheels still (steering unchanged)."""
        c = self.client
        p.resetBaseVelocity(self.body_id, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=c)
        angle = self._steer_angle()
        for joint in _STEER_JOINTS:
            p.resetJointState(self.body_id, joint, angle, 0.0, physicsClientId=c)
        for joint in _WHEEL_JOINTS:
            p.resetJointState(self.body_id, joint, 0.0, 0.0, physicsClientId=c)
        self._set_motors(self._steer_angle(), 0.0)

    def _steer_angle(self) -> float:
        """The knuckles' angle (rad): both are driven to the same target."""
        states = p.getJointStates(self.body_id, _STEER_JOINTS, physicsClientId=self.client)
        return 0.5 * (states[0][0] + states[1][0])

    def steering_angle_deg(self) -> float:
        """The front wheels' steering angle now (deg, positive = left), lagging the command."""
        return math.degrees(self._steer_angle())
