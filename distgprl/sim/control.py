"""The control loop of the task simulations: Cartesian TCP poses tracked with dynamics.

`ControlLoop.run` executes poses, one per control period: IK (the branch nearest the
previous joint target), joint position control linearly interpolated over the physics
substeps with feed-forward velocity, the world's kinematic bodies moved every physics step,
contacts checked after every physics step and the clearance after every control period.
It works on any `ControlledScene` (a `distgprl.sim.tasks.base.TaskSim`) with any
`distgprl.sim.robot.Robot`. Everything a segment commands depends on its poses, the previous
joint target and the clock only, never on the physics: its joint targets (one IK pass,
`Robot.ik_segment`), their interpolation and feed-forward velocities, the kinematic bodies'
poses (`ControlledScene.kinematic_schedule`) and the conveyed object's path
(`ControlledScene.convey_schedule`) are computed before it executes (`_SegmentPlan`), and
the loop then only calls PyBullet and reads contacts and clearances.

The per-step PyBullet functions are bound once in `BulletCalls` (a `BulletClient`'s
attribute look-up costs microseconds per call) and called with positional arguments;
benchmarks may wrap its attributes with timers. The plan performs the same IEEE operations,
in the same order, as the per-step arithmetic it replaces (the per-step loop is
kept in ``tests/sim/_reference_control.py`` and the two agree bit for bit).
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


_NO_LINKS: frozenset[int] = frozenset()


@dataclass(frozen=True)
class SegmentResult:
    """Outcome of executing one trajectory segment.

    Attributes:
        collision: any contact (penetration distance <= 0) between a robot link or the
            tool and an obstacle during the segment, checked after every physics step and
            at every control step (exempt pairs are listed by the task).
        min_clearance: minimum distance (m) between robot/tool and the obstacles over the
            segment's control steps, capped at the task's ``clearance_cutoff`` (and at the
            run's ``clearance_below`` when given); <= 0 on contact.
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

    def kinematic_schedule(
        self, times: list[float]
    ) -> list[
        tuple[tuple[int, tuple[float, float, float], tuple[float, float, float, float]], ...]
    ]:
        """Per time of ``times`` (s), the resets (body, position (m), orientation (x, y, z,
        w)) that put the kinematically moved obstacles at their poses for that time (pure:
        nothing moves)."""
        ...

    def kinematic_reached(self, time: float) -> None:
        """Record that the kinematic obstacles stand at their poses for ``time`` (s) (the
        loop made the resets of `kinematic_schedule`)."""
        ...

    def convey_schedule(
        self, times: list[float]
    ) -> list[
        tuple[int, tuple[float, float, float], tuple[float, float, float, float], tuple[float, ...]]
    ]:
        """Per time of ``times`` (s), (body, position (m), orientation, linear velocity
        (m/s)) of the conveyed object where the conveyor has it then (pure)."""
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
        then the clearance if it is under ``below``, else ``below`` (issue 29). Each body's
        query looks no farther than the minimum found so far, which culls the same pairs or
        more and finds the same minimum (issue 66).
        """
        best = self.clearance_cutoff if below is None else min(below, self.clearance_cutoff)
        closest_points = self.calls.closest_points
        robot_body = self.robot.body
        for body, exempt in self._clearance_queries:
            for point in closest_points(robot_body, body, best):
                if point[8] < best and (exempt is None or point[3] not in exempt):
                    best = point[8]
        return best

    def run(
        self,
        scene: ControlledScene,
        poses: np.ndarray,
        stop_on_collision: bool = False,
        clearance_below: float | None = None,
    ) -> SegmentResult:
        """Track Cartesian TCP poses in ``scene``, one per control period, with dynamics.

        Args:
            scene: the world (clock, last joint target, kinematic bodies, conveyed object).
            poses: shape (n, 6): x, y, z (m), rx, ry, rz (rad), world frame. Pose k is the
                target at the end of control period k of this segment.
            stop_on_collision: end execution after the control period in which a collision
                is detected (a protective stop); the remaining poses are not executed.
            clearance_below: optional, m, > 0: only a clearance under it matters to the
                caller (e.g. the episode's minimum so far), so the clearance queries look no
                farther; ``min_clearance`` is then min(clearance_below, the segment's).

        Each pose is converted by IK (branch nearest the previous joint target) into a
        joint target; the joint position controllers move to it, linearly interpolated
        over ``physics.substeps`` physics steps, with feed-forward velocity. Object and
        obstacles keep moving. Collisions are checked after every physics step,
        clearance at every control step. Nothing of this depends on the physics but the
        contacts and the clearance, so the segment's joint targets (one IK pass,
        `Robot.ik_segment`, issue 49), their interpolation, the kinematic bodies' poses and
        the conveyed object's path are computed before it executes (`_SegmentPlan`;
        issue 66), the same IEEE operations in the same order as per physics step.
        """
        poses = np.asarray(poses, dtype=float)
        if poses.ndim != 2 or poses.shape[1] != 6 or not np.all(np.isfinite(poses)):
            raise UserInputError(f"poses must be a finite (n, 6) array, got shape {poses.shape}")
        robot = self.robot
        command = robot.command
        step_simulation, contact_points = self.calls.step_simulation, self.calls.contact_points
        reset_base_pose, reset_base_velocity = (
            self.calls.reset_base_pose,
            self.calls.reset_base_velocity,
        )
        clearance_now = self.clearance
        robot_body = robot.body
        collision = False
        min_clearance = self.clearance_cutoff
        if clearance_below is not None:
            if not clearance_below > 0.0:
                raise ValueError(f"clearance_below must be > 0 m, got {clearance_below}")
            min_clearance = min(min_clearance, float(clearance_below))
        released = scene.object_released
        q_start = scene.q_command
        joints, reached = robot.ik_segment(poses, q_start)
        plan = _SegmentPlan(joints, q_start, scene.time, self.physics)
        moves = scene.kinematic_schedule(plan.times)
        conveyed = None if released else scene.convey_schedule(plan.times)
        substeps = self.physics.substeps
        executed = 0
        time = scene.time
        try:
            for index in range(plan.count):
                first = index * substeps
                velocity = plan.velocities[index]
                for substep, target in enumerate(plan.targets[index]):
                    command(target, velocity)
                    for body, position, orientation in moves[first + substep]:
                        reset_base_pose(body, position, orientation)
                    step_simulation()
                    touched_object, hit = self._scan_contacts(contact_points(robot_body))
                    collision = collision or hit
                    if touched_object and not released:
                        released = True
                        scene.release_object()
                    if not released:
                        body, position, orientation, linear = conveyed[first + substep]  # type: ignore[index]  # noqa: E501
                        reset_base_pose(body, position, orientation)
                        reset_base_velocity(body, linear, (0.0, 0.0, 0.0))
                time = plan.times[first + substeps - 1]
                clearance = clearance_now(min_clearance)  # only a new minimum matters
                if clearance < min_clearance:
                    min_clearance = clearance
                executed += 1
                if stop_on_collision and (collision or min_clearance <= 0.0):
                    break
        finally:
            if executed:
                scene.time = plan.clock[executed - 1]
                scene.q_command = joints[executed - 1].copy()
                scene.kinematic_reached(time)
        if min_clearance <= 0.0:
            collision = True
        return SegmentResult(
            collision=collision,
            min_clearance=float(min_clearance),
            ik_failures=int(plan.count - np.count_nonzero(reached)),
            steps=executed,
            peak_joint_speed=plan.peak_speed(executed),
            stopped=executed < plan.count,
        )

    def _scan_contacts(self, contacts) -> tuple[bool, bool]:
        """One physics step's contacts of the robot (pybullet contact tuples): whether it
        touches the manipulated object, and whether it touches an obstacle on a link not
        exempt from that obstacle (a collision). Contacts at positive distance are ignored."""
        object_body, obstacles, exempt = self.object_body, self._obstacle_set, self.exempt_links
        touched_object = hit = False
        for contact in contacts:
            if contact[8] > 0.0:
                continue
            other = contact[2]
            if other == object_body:
                touched_object = True
            elif other in obstacles and contact[3] not in exempt.get(other, _NO_LINKS):
                hit = True
        return touched_object, hit


class _SegmentPlan:
    """What a segment commands, computed before it executes (plain floats, the same IEEE
    operations in the same order as computed per physics step).

    Args:
        joints: the segment's joint targets (n, n_joints), rad (`Robot.ik_segment`; an
            unreachable pose's row holds the previous target).
        q_start: the joint target before the segment (n_joints,), rad.
        start_time: the world's clock at the segment's start, s.
        physics: ``substeps`` physics steps of ``physics_dt`` per pose.

    Attributes:
        count: n.
        targets: per period, per substep, the interpolated joint targets (lists of floats):
            previous + ((s + 1) / substeps) (target - previous).
        velocities: per period, the feed-forward velocities (target - previous) / period.
        speeds: per period, the largest |velocity| over the joints, rad/s.
        times: the world's clock after each physics step (n * substeps,), s.
        clock: the world's clock after each period (n,), s.
    """

    def __init__(self, joints: np.ndarray, q_start: np.ndarray, start_time: float, physics) -> None:
        substeps, dt = physics.substeps, physics.physics_dt
        self.count = int(joints.shape[0])
        previous = np.empty_like(joints)
        if self.count:
            previous[0] = q_start
            previous[1:] = joints[:-1]
        delta = joints - previous
        velocity = delta * (1.0 / (dt * substeps))
        fractions = np.array([(s + 1) / substeps for s in range(substeps)])
        targets = previous[:, None, :] + fractions[None, :, None] * delta[:, None, :]
        self.targets = targets.tolist()
        self.velocities = velocity.tolist()
        self.speeds = np.abs(velocity).max(axis=1) if self.count else np.zeros(0)
        offsets = [(s + 1) * dt for s in range(substeps)]
        period = substeps * dt
        times: list[float] = []
        clock: list[float] = []
        now = float(start_time)
        for _ in range(self.count):
            times.extend([now + offset for offset in offsets])
            now += period
            clock.append(now)
        self.times = times
        self.clock = clock

    def peak_speed(self, executed: int) -> float:
        """The largest commanded joint speed (rad/s) over the first ``executed`` periods
        (0 for none)."""
        return float(max(0.0, float(self.speeds[:executed].max()))) if executed else 0.0
