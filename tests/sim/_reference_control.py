"""The v7 control loop, kept verbatim as the reference of `tests/sim/test_control_equivalence.py`.

`reference_run` is `distgprl.sim.control.ControlLoop.run` as environment v7 ran it (commit
8e0131e): per control period the interpolated joint targets computed in the loop, the joint
command with keyword arguments (`reference_command`, v7's `UR5e.command`), the kinematic
obstacles and the conveyed object moved by v7's per-physics-step formulas
(`reference_move_kinematic`, `reference_convey`), and the clearance queried against every
obstacle body with one threshold (`reference_clearance`).
"""

from __future__ import annotations

import math

import numpy as np
import pybullet

from distgprl.sim.control import SegmentResult
from distgprl.sim.tasks.dbm import DBMSim
from distgprl.sim.tasks.dcp import DCPSim


def reference_command(sim, q_target, qd_target) -> None:
    """v7's `UR5e.command`: keyword arguments, lists of floats."""
    robot = sim.robot
    robot.client.setJointMotorControlArray(
        robot.body,
        robot.joint_indices,
        pybullet.POSITION_CONTROL,
        targetPositions=np.asarray(q_target, dtype=float).tolist(),
        targetVelocities=np.asarray(qd_target, dtype=float).tolist(),
        forces=robot.max_forces.tolist(),
        positionGains=[robot.position_gain] * 6,
        velocityGains=[1.0] * 6,
    )


def reference_move_kinematic(sim, time: float) -> None:
    """v7's `DCPSim.move_kinematic` / `DBMSim.move_kinematic`."""
    if isinstance(sim, DCPSim):
        scene = sim.scene
        phase = 2.0 * math.pi * time / scene.obstacle_period + scene.obstacle_phase
        line_x, line_y = sim._obstacle_line.tolist()
        height = scene.obstacle_half + 1e-4
        position = (line_x + scene.obstacle_amplitude * math.sin(phase), line_y, height)
        sim._obstacle_position = position
        sim.calls.reset_base_pose(sim.obstacle_body, position, (0.0, 0.0, 0.0, 1.0))
    elif isinstance(sim, DBMSim):
        start = sim._other_start
        position = (start[0], start[1] + sim.scene.belt_speed * time, start[2])
        sim._other_position = position
        sim.calls.reset_base_pose(sim.other_bar_body, position, (0.0, 0.0, 0.0, 1.0))
    else:  # pragma: no cover - the reference knows the two tasks
        raise TypeError(type(sim).__name__)


def reference_convey(sim, time: float) -> None:
    """v7's `TaskSim.convey_object`."""
    if sim._object_released:
        return
    x0, y0, z0, vx, vy = sim._conveyor
    sim.calls.reset_base_pose(
        sim.object_body, (x0 + vx * time, y0 + vy * time, z0), sim._object_quaternion
    )
    sim.calls.reset_base_velocity(sim.object_body, sim._object_velocity_list, (0.0, 0.0, 0.0))


def reference_clearance(loop, below: float | None = None) -> float:
    """v7's `ControlLoop.clearance`: every body queried with the same threshold."""
    cutoff = loop.clearance_cutoff if below is None else min(below, loop.clearance_cutoff)
    best = cutoff
    for body, exempt in loop._clearance_queries:
        for point in loop.calls.closest_points(bodyA=loop.robot.body, bodyB=body, distance=cutoff):
            if point[8] < best and (exempt is None or point[3] not in exempt):
                best = point[8]
    return best


def reference_run(sim, poses: np.ndarray, stop_on_collision: bool = False) -> SegmentResult:
    """v7's `ControlLoop.run` on ``sim`` (its loop, its robot, its scene)."""
    loop = sim.control
    scene = sim
    poses = np.asarray(poses, dtype=float)
    robot = loop.robot
    step_simulation, contact_points = loop.calls.step_simulation, loop.calls.contact_points
    substeps = loop.physics.substeps
    dt = loop.physics.physics_dt
    robot_body = robot.body
    object_body = loop.object_body
    obstacles = loop._obstacle_set
    exempt = loop.exempt_links
    no_links: frozenset[int] = frozenset()
    collision = False
    min_clearance = loop.clearance_cutoff
    failures = 0
    peak_speed = 0.0
    substep_plan = [((s + 1) * dt, (s + 1) / substeps) for s in range(substeps)]
    period = substeps * dt
    inverse_dt = 1.0 / (loop.physics.physics_dt * substeps)
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
                reference_command(
                    sim,
                    [p + fraction * d for p, d in zip(q_previous, delta, strict=True)],
                    velocity,
                )
                time = now + offset
                reference_move_kinematic(sim, time)
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
                    reference_convey(sim, time)
            now += period
            q_previous = q_target
            clearance = reference_clearance(loop, min_clearance)
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
