"""One decision: the plan's segment through the gate into the world; only what the world
executed is marked commanded; a refused segment moves nothing."""

from __future__ import annotations

import numpy as np

from distgprl.envs.episode import Reviewed, execute_segment, plan_segment
from distgprl.envs.world import SegmentReport


class _Plan:
    def __init__(self) -> None:
        self.step_index = 0
        self.actions: list[np.ndarray] = []
        self.marked: list[tuple[int, np.ndarray]] = []

    def apply_action(self, step, action):
        self.actions.append(action)
        return 2.0 * action

    def segment_poses(self, step):
        return np.arange(30.0).reshape(5, 6) + step

    def mark_commanded(self, step, poses):
        self.marked.append((step, poses))


class _World:
    control_dt = 0.04

    def __init__(self, steps: int) -> None:
        self.steps = steps
        self.executed: list[tuple[np.ndarray, object, bool]] = []

    def execute(self, poses, joints=None, last=True):
        self.executed.append((poses, joints, last))
        return SegmentReport(min(self.steps, len(poses)), stopped=self.steps < len(poses))


class _Gate:
    def __init__(self, refuse: bool) -> None:
        self.refuse = refuse
        self.tracked: list[int] = []

    def review(self, step, poses):
        return Reviewed(poses + 100.0, poses, joints=np.zeros((len(poses), 6)), refused=self.refuse)

    def executed(self, reviewed, report):
        self.tracked.append(report.steps)


def test_the_plan_gets_the_action_and_gives_the_segment():
    plan = _Plan()
    change, poses = plan_segment(plan, 1, np.ones(6))
    assert np.array_equal(change, 2.0 * np.ones(6)) and np.array_equal(poses, plan.segment_poses(1))


def test_only_the_executed_part_of_the_path_is_marked_and_the_plan_moves_on():
    plan, world, gate = _Plan(), _World(steps=3), _Gate(refuse=False)
    poses = plan.segment_poses(0)
    decision = execute_segment(plan, world, 0, poses, gate, last=False)
    executed, joints, last = world.executed[0]
    assert np.array_equal(executed, poses + 100.0) and joints is not None and last is False
    step, marked = plan.marked[0]
    assert step == 0 and np.array_equal(marked, poses[:3])  # the path, not the shifted poses
    assert plan.step_index == 1 and gate.tracked == [3] and not decision.refused


def test_a_refused_segment_moves_nothing_and_the_plan_stays():
    plan, world, gate = _Plan(), _World(steps=5), _Gate(refuse=True)
    decision = execute_segment(plan, world, 0, plan.segment_poses(0), gate)
    assert decision.refused and decision.report is None
    assert not world.executed and not plan.marked and plan.step_index == 0 and not gate.tracked


def test_without_a_gate_the_poses_go_as_planned():
    plan, world = _Plan(), _World(steps=5)
    poses = plan.segment_poses(2)
    execute_segment(plan, world, 2, poses)
    assert world.executed[0][0] is poses and world.executed[0][1] is None


def test_the_tally_adds_the_segments_up():
    from distgprl.envs.episode import EpisodeTally

    tally = EpisodeTally()
    tally.add(SegmentReport(3, min_clearance=0.02, peak_joint_speed=0.5))
    tally.add(SegmentReport(2, collision=True, min_clearance=-0.001, peak_joint_speed=0.3))
    tally.add(SegmentReport(1, min_clearance=0.05, peak_joint_speed=0.1))
    assert tally == EpisodeTally(True, -0.001, 0.5, 6)
