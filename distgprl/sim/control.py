"""The control loop of the task simulations: Cartesian TCP poses tracked with dynamics.

`ControlLoop.run` executes poses, one per control period: IK (the branch nearest the
previous joint target), joint position control linearly interpolated over the physics
substeps with feed-forward velocity, the world's kinematic bodies moved every physics step,
contacts checked after every physics step and the clearance after every control period.
It works on any `ControlledScene` (a `distgprl.sim.tasks.base.TaskSim`) with any
`distgprl.sim.robot.Robot`. A segment's joint targets are computed before it executes, in
one call (`Robot.ik_segment`): they depend on the poses and the previous target only.

The per-step PyBullet functions are bound once in `BulletCalls` (a `BulletClient`'s
attribute look-up costs microseconds per call); benchmarks may wrap its attributes with
timers. The loop runs on plain floats: the same IEEE operations, in the same order, as
array arithmetic would do, without its per-call overhead (issue 29).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from distgprl.errors import UserInputError

if TYPE_CHECKING:
    from pybullet_utils.bullet_client import BulletClient

    from distgprl.sim.bullet import PhysicsConfig
    from distgprl.sim.robot import Robot

__all__ = ["BulletCalls", "ControlLoop", "ControlledScene", "SegmentResult"]


@dataclass(frozen=True)
class SegmentResult:
    """Outcome of executing one trajectory segment.

    Attributes:
        collision: any contact (penetration distance <= 0) between a robot link or the
            tool and an obstacle during the segment, checked after every physics step and
            at every control step (exempt pairs are listed by the task).
        min_clearance: minimum distance (m) between robot/tool and the obstacles over the
            segment's control steps, capped at the task's ``clearance_cutoff``; <= 0 on
            contact.
        ik_failures: poses with no IK solution within the joint limits (the previous joint
            target is then held).
        steps: poses executed (control periods).
        peak_joint_speed: largest commanded joint speed (rad/s) in the segment: the joint
            targets' finite differences at the control period (the first from the previous
            target), maximum over joints and periods; the quantity the hardware safety
            layer bounds (`distgprl.limits.SafetyLimits.max_joint_speed`).
        stopped: execution stopped at a collision before the segment's last pose (a
            protective stop; only with ``execute(..., stop_on_collision=True)``).
    """

    collision: bool
    min_clearance: float
    ik_failures: int
    steps: int
    peak_joint_speed: float = 0.0
    stopped: bool = False


class BulletCalls:
    """The PyBullet functions called every physics step, bound to one client once.

    Attributes (callables with PyBullet's signatures, the client id bound):
        step_simulation, contact_points, closest_points, reset_base_pose
        (``resetBasePositionAndOrientation``), reset_base_velocity.
    """

    def __init__(self, client: BulletClient) -> None:
        self.step_simulation = client.stepSimulation
        self.contact_points = client.getContactPoints
        self.closest_points = client.getClosestPoints
        self.reset_base_pose = client.resetBasePositionAndOrientation
        self.reset_base_velocity = client.resetBaseVelocity


class ControlledScene(Protocol):
    """What the control loop reads and moves in a task's world (a `TaskSim`).

    Attributes:
        time: the world's clock, s (advanced by the loop, one control period per pose).
        q_command: the last joint target (n_joints,), rad (the next IK's reference).
        object_released: whether the robot has touched the manipulated object.
    """

    time: float
    q_command: np.ndarray

    @property
    def object_released(self) -> bool: ...

    def release_object(self) -> None:
        """The robot touched the object: from now on it moves under contact physics."""
        ...

    def move_kinematic(self, time: float) -> None:
        """Put the kinematically moved obstacles at their poses for ``time`` (s)."""
        ...

    def convey_object(self, time: float) -> None:
        """Put the (not yet released) conveyed object where the conveyor has it at ``time``."""
        ...


class ControlLoop:
    """Pose tracking, contact and clearance checks of one robot in one task's world.

    Args:
        robot: the robot (its ``body`` is the contact and clearance queries' ``bodyA``).
        calls: the client's per-step PyBullet functions.
        physics: physics settings (``substeps`` physics steps of ``physics_dt`` per pose).
        object_body: the manipulated object's body id (a contact releases it).
        obstacle_bodies: the obstacles' body ids (a contact is a collision).
        exempt_links: per obstacle body, robot link indices whose contacts do not count.
        clearance_cutoff: distances above this (m) are reported as this value.
    """

    def __init__(
        self,
        robot: Robot,
        calls: BulletCalls,
        physics: PhysicsConfig,
        object_body: int,
        obstacle_bodies: tuple[int, ...],
        exempt_links: dict[int, frozenset[int]],
        clearance_cutoff: float,
    ) -> None:
        self.robot = robot
        self.calls = calls
        self.physics = physics
        self.object_body = object_body
        self.obstacle_bodies = tuple(obstacle_bodies)
        self.exempt_links = dict(exempt_links)
        self.clearance_cutoff = clearance_cutoff
        self._obstacle_set = frozenset(self.obstacle_bodies)
        self._clearance_queries = tuple(
            (body, self.exempt_links.get(body)) for body in self.obstacle_bodies
        )

    def clearance(self, below: float | None = None) -> float:
        """Current minimum distance (m) robot/tool to obstacles, capped at the cutoff.

        ``below`` (m, at most the cutoff): only distances under it matter to the caller
        (the running minimum of a segment), so the queries look no farther; the result is
        then the clearance if it is under ``below``, else ``below`` (issue 29).
        """
        cutoff = self.clearance_cutoff if below is None else min(below, self.clearance_cutoff)
        best = cutoff
        closest_points = self.calls.closest_points
        robot_body = self.robot.body
        for body, exempt in self._clearance_queries:
            for point in closest_points(bodyA=robot_body, bodyB=body, distance=cutoff):
                if point[8] < best and (exempt is None or point[3] not in exempt):
                    best = point[8]
        return best

    def run(
        self, scene: ControlledScene, poses: np.ndarray, stop_on_collision: bool = False
    ) -> SegmentResult:
        """Track Cartesian TCP poses in ``scene``, one per control period, with dynamics.

        Args:
            scene: the world (clock, last joint target, kinematic bodies, conveyed object).
            poses: shape (n, 6): x, y, z (m), rx, ry, rz (rad), world frame. Pose k is the
                target at the end of control period k of this segment.
            stop_on_collision: end execution after the control period in which a collision
                is detected (a protective stop); the remaining poses are not executed.

        Each pose is converted by IK (branch nearest the previous joint target) into a
        joint target; the joint position controllers move to it, linearly interpolated
        over ``physics.substeps`` physics steps, with feed-forward velocity. Object and
        obstacles keep moving. Collisions are checked after every physics step,
        clearance at every control step. The targets depend on the poses only, so the
        segment's IK runs in one pass before it executes (`Robot.ik_segment`, issue 49).
        """
        poses = np.asarray(poses, dtype=float)
        if poses.ndim != 2 or poses.shape[1] != 6 or not np.all(np.isfinite(poses)):
            raise UserInputError(f"poses must be a finite (n, 6) array, got shape {poses.shape}")
        robot = self.robot
        command = robot.command
        step_simulation, contact_points = self.calls.step_simulation, self.calls.contact_points
        move_kinematic, convey_object = scene.move_kinematic, scene.convey_object
        clearance_now = self.clearance
        substeps = self.physics.substeps
        dt = self.physics.physics_dt
        robot_body = robot.body
        object_body = self.object_body
        obstacles = self._obstacle_set
        exempt = self.exempt_links
        no_links: frozenset[int] = frozenset()
        collision = False
        min_clearance = self.clearance_cutoff
        failures = 0
        peak_speed = 0.0
        # substep s of a period: time offset (s + 1) dt and interpolation fraction (s + 1) / n
        substep_plan = [((s + 1) * dt, (s + 1) / substeps) for s in range(substeps)]
        period = substeps * dt
        inverse_dt = 1.0 / (self.physics.physics_dt * substeps)
        released = scene.object_released
        now = scene.time
        q_command = scene.q_command
        q_previous = q_command.tolist()
        joints, reached = robot.ik_segment(poses, q_command)
        targets = joints.tolist()
        executed = 0
        try:
            for index, ok in enumerate(reached.tolist()):
                if ok:
                    q_command = joints[index]
                    q_target = targets[index]
                else:
                    failures += 1
                    q_target = q_previous
                delta = [t - p for t, p in zip(q_target, q_previous, strict=True)]
                velocity = [d * inverse_dt for d in delta]
                speed = max([abs(v) for v in velocity])
                if speed > peak_speed:
                    peak_speed = speed
                for offset, fraction in substep_plan:
                    command(
                        [p + fraction * d for p, d in zip(q_previous, delta, strict=True)], velocity
                    )
                    time = now + offset
                    move_kinematic(time)
                    step_simulation()
                    for contact in contact_points(bodyA=robot_body):
                        if contact[8] > 0.0:
                            continue
                        other = contact[2]
                        if other == object_body:
                            if not released:
                                released = True
                                scene.release_object()
                        elif other in obstacles and contact[3] not in exempt.get(other, no_links):
                            collision = True
                    if not released:
                        convey_object(time)
                now += period
                q_previous = q_target
                clearance = clearance_now(min_clearance)  # only a new minimum matters
                if clearance < min_clearance:
                    min_clearance = clearance
                executed += 1
                if stop_on_collision and (collision or min_clearance <= 0.0):
                    break
        finally:
            scene.time = now
            scene.q_command = np.array(q_command, dtype=float)
        if min_clearance <= 0.0:
            collision = True
        return SegmentResult(
            collision=collision,
            min_clearance=float(min_clearance),
            ik_failures=failures,
            steps=executed,
            peak_joint_speed=peak_speed,
            stopped=executed < int(poses.shape[0]),
        )
