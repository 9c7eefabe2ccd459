"""The control loop's segment plan (issue 66) executes exactly what v7's loop executed.

`ControlLoop.run` now computes a segment's interpolated joint targets, feed-forward
velocities, kinematic obstacle poses and conveyor path before it executes, passes PyBullet
positional arguments, and lets each clearance query look no farther than the minimum found
so far. None of it changes an IEEE operation or an argument PyBullet receives, so the
tolerance is **zero**: on fixed evaluation TCs of both tasks, the TC's expert demonstration
(contact, release, pushing / lifting) and a lowered copy of it that collides (with and
without the protective stop) give bit-identical segment results (collision, min clearance,
IK failures, steps, peak joint speed, stopped) and bit-identical simulator states after
every chunk (clock, joint target, joint positions, TCP pose, object pose, obstacle poses,
clearance) against v7's loop kept verbatim in `_reference_control.py`.
"""

from __future__ import annotations

import numpy as np
import pytest
from _reference_control import reference_run

from distgprl.sim.tasks import get_task
from distgprl.sim.tasks.base import resample_to_control

TCS_PER_TASK = 4
CHUNKS = 3


def _state(sim) -> dict[str, np.ndarray]:
    shapes = sim.moving_obstacle_shapes()
    return {
        "time": np.array([sim.time]),
        "q_command": sim.q_command,
        "joints": sim.joint_positions(),
        "tcp": sim.tcp_pose(),
        "object": np.concatenate([sim.object_position(), sim.object_orientation()]),
        "obstacles": np.concatenate([np.asarray(s.position, float) for s in shapes]),
        "clearance": np.array([sim.clearance()]),
        "released": np.array([sim.object_released]),
    }


def _episodes(task: str):
    """(name, poses, stop_on_collision) per fixed TC: the expert's demonstration, and the
    same lowered by 4 cm from its middle on (into the table / the rollers)."""
    spec = get_task(task)
    for k, tc in enumerate(spec.evaluation_tcs(TCS_PER_TASK)):
        times, poses = spec.expert(tc)
        poses = resample_to_control(times, poses, 1.0 / 25.0)
        lowered = poses.copy()
        lowered[len(poses) // 2 :, 2] -= 0.04
        yield tc, f"{task}-tc{k}-demo", poses, False
        yield tc, f"{task}-tc{k}-lowered", lowered, k % 2 == 0


@pytest.mark.parametrize("task", ["dcp", "dbm"])
def test_the_planned_loop_is_v7s_loop_bit_for_bit(task):
    spec = get_task(task)
    new_sim, old_sim = spec.make_sim(), spec.make_sim()
    collided = 0
    try:
        for tc, name, poses, stop in _episodes(task):
            new_sim.reset(tc)
            old_sim.reset(tc)
            for chunk in np.array_split(np.arange(len(poses)), CHUNKS):
                new = new_sim.execute(poses[chunk], stop_on_collision=stop)
                old = reference_run(old_sim, poses[chunk], stop_on_collision=stop)
                assert new == old, name
                for key, value in _state(old_sim).items():
                    assert np.array_equal(_state(new_sim)[key], value), (name, key)
                collided += old.collision
                if stop and old.collision:
                    break
    finally:
        new_sim.close()
        old_sim.close()
    assert collided > 0  # the lowered copies exercise the collision paths
