"""The simulator world: a segment in chunks, stopping at a contact, the tool clearance after
each chunk, the clearance cap from the episode's minimum."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from distgprl.envs.world import SimWorld


@dataclass
class _Result:
    collision: bool
    min_clearance: float
    steps: int
    peak_joint_speed: float
    stopped: bool = False


class _FakeSim:
    """Executes chunks; a contact at the period whose pose has x < 0."""

    control_dt = 0.04

    def __init__(self) -> None:
        self.calls: list[tuple[int, float | None]] = []

    def execute(self, poses, stop_on_collision=False, clearance_below=None):
        self.calls.append((len(poses), clearance_below))
        contact = np.flatnonzero(poses[:, 0] < 0)
        if len(contact) and stop_on_collision:
            steps = int(contact[0]) + 1
            return _Result(True, -0.001, steps, 1.0, stopped=steps < len(poses))
        return _Result(bool(len(contact)), float(poses[:, 1].min()), len(poses), 0.5)


def _poses(n: int, contact_at: int | None = None) -> np.ndarray:
    poses = np.zeros((n, 6))
    poses[:, 0] = 1.0
    poses[:, 1] = np.linspace(0.2, 0.1, n)
    if contact_at is not None:
        poses[contact_at, 0] = -1.0
    return poses


def test_a_segment_runs_in_its_samples_and_reports_the_tool_clearance_after_each():
    sim = _FakeSim()
    probes = iter([np.array([0.3]), np.array([0.2]), np.array([0.1])])
    world = SimWorld(sim, samples=3, tool_clearance=lambda: next(probes))
    report = world.execute(_poses(10))
    assert [n for n, _ in sim.calls] == [4, 3, 3]
    assert report.steps == 10 and not report.stopped and not report.collision
    assert [float(c[0]) for c in report.tool_clearances] == [0.3, 0.2, 0.1]
    assert report.min_clearance == 0.1 and report.peak_joint_speed == 0.5


def test_a_contact_stops_the_segment_in_its_chunk():
    sim = _FakeSim()
    world = SimWorld(sim, stop_on_collision=True, samples=2)
    report = world.execute(_poses(10, contact_at=2))
    assert len(sim.calls) == 1 and report.steps == 3
    assert report.collision and report.stopped and report.min_clearance == -0.001


def test_the_cap_is_the_episode_minimum_so_far_and_a_new_episode_forgets_it():
    sim = _FakeSim()
    world = SimWorld(sim, samples=2, cap_at_minimum=True)
    world.execute(_poses(4))
    assert sim.calls[0][1] is None  # no minimum yet
    assert sim.calls[1][1] == float(_poses(4)[:2, 1].min())  # the first chunk's
    world.begin_episode()
    world.execute(_poses(2))
    assert sim.calls[2][1] is None
