"""Task registry, task configurations, TC samplers and the fixed evaluation sets."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.errors import UserInputError
from distgprl.sim.tasks import TASKS, get_task
from distgprl.sim.tasks.base import TaskConfig
from distgprl.sim.tasks.dbm import SCENE as DBM_SCENE
from distgprl.sim.tasks.dcp import SCENE as DCP_SCENE


def test_registry_and_unknown_name():
    """Both tasks are registered; an unknown name raises UserInputError listing valid names."""
    assert set(TASKS) == {"dcp", "dbm"}
    assert get_task("dcp").name == "dcp"
    with pytest.raises(UserInputError, match="dcp, dbm"):
        get_task("cube")


def test_task_config_validates_and_round_trips():
    """TCs store two finite floats per offset, reject bad input and survive to_dict/from_dict."""
    tc = TaskConfig(object_offset=np.array([0.1, -0.05]), obstacle_offset=[0.0, 0.02])
    assert tc.object_offset == (0.1, -0.05)
    assert TaskConfig.from_dict(tc.to_dict()) == tc
    with pytest.raises(UserInputError):
        TaskConfig(object_offset=(0.1, 0.2, 0.3))
    with pytest.raises(UserInputError):
        TaskConfig(object_offset=(float("nan"), 0.0))


def test_dcp_sampler_ranges():
    """DCP: object offsets within 0.20 m, obstacle offsets within 0.10 m, spread over the disks."""
    rng = np.random.default_rng(0)
    tcs = [get_task("dcp").sample_tc(rng) for _ in range(2000)]
    objects = np.array([tc.object_offset for tc in tcs])
    obstacles = np.array([tc.obstacle_offset for tc in tcs])
    assert np.linalg.norm(objects, axis=1).max() <= DCP_SCENE.object_offset_radius
    assert np.linalg.norm(obstacles, axis=1).max() <= DCP_SCENE.obstacle_offset_radius
    assert np.linalg.norm(objects, axis=1).max() > 0.19
    assert np.all(np.abs(objects.mean(axis=0)) < 0.01)


def test_dbm_sampler_ranges():
    """DBM (scene revision 2): offsets in the xy-plane — along the belt within +-0.20 m,
    across it within the rails (+-3.5 cm: the bar's ends keep 5 mm from the rails' inner
    faces) — and the bars never closer than the gap."""
    rng = np.random.default_rng(0)
    tcs = [get_task("dbm").sample_tc(rng) for _ in range(2000)]
    objects = np.array([tc.object_offset for tc in tcs])
    obstacles = np.array([tc.obstacle_offset for tc in tcs])
    lateral = DBM_SCENE.lateral_range
    inner_face = DBM_SCENE.rail_offset - DBM_SCENE.rail_half_extents[0]
    assert lateral == pytest.approx(inner_face - DBM_SCENE.bar_half_extents[0] - 0.005)
    assert lateral == pytest.approx(0.035)
    for offsets in (objects, obstacles):
        assert np.abs(offsets[:, 0]).max() <= lateral and np.abs(offsets[:, 0]).max() > 0.03
        assert offsets[:, 0].std() > 0.015  # spread over the range, not pinned
    assert np.abs(objects[:, 1]).max() <= 0.2 and np.abs(obstacles[:, 1]).max() <= 0.2
    assert np.abs(objects[:, 1]).max() > 0.19
    gap = (
        (DBM_SCENE.target_start_y + objects[:, 1])
        - (DBM_SCENE.other_start_y + obstacles[:, 1])
        - 2 * DBM_SCENE.bar_half_extents[1]
    )
    assert gap.min() >= DBM_SCENE.min_bar_gap


@pytest.mark.parametrize("name", ["dcp", "dbm"])
def test_evaluation_sets_are_fixed(name):
    """The 100 evaluation TCs are the same on every call, distinct and differ from the others."""
    spec = get_task(name)
    first = spec.evaluation_tcs()
    assert len(first) == 100
    assert first == spec.evaluation_tcs(100)
    assert len(set(first)) == 100
    assert spec.evaluation_tcs(10) == first[:10]
    curve = spec.training_curve_tcs()
    assert len(curve) == 20 and curve == spec.training_curve_tcs()
    assert not set(curve) & set(first)
    assert 0.0 < spec.interaction_time < 1.0
    assert spec.demo_path.is_file()


def test_every_registry_reads_the_task_modules_declarations():
    """Each task module's ``TASK`` is what `TASKS` holds (in `TASK_NAMES` order); its scene
    revision is the pybullet-free catalogue's (`SCENE_REVISIONS`, which the config hashes
    read, values unchanged: dcp 0, dbm 2); its expert and simulation class are the module's."""
    from distgprl.data import SCENE_REVISIONS, TASK_NAMES
    from distgprl.sim.tasks import dbm, dcp

    assert tuple(TASKS) == TASK_NAMES
    assert TASKS["dcp"] is dcp.TASK and TASKS["dbm"] is dbm.TASK
    assert SCENE_REVISIONS == {"dcp": 0, "dbm": 2}
    for name, module in (("dcp", dcp), ("dbm", dbm)):
        spec = TASKS[name]
        assert spec.name == name
        assert spec.scene_revision == SCENE_REVISIONS[name]
        assert spec.expert is getattr(module, f"{name}_expert")
        assert spec.make_sim is getattr(module, f"{name.upper()}Sim")


def test_a_task_simulation_runs_the_robot_its_factory_builds():
    """`TaskSim` builds its robot with the injected factory (the UR5e only by default), and
    the robot satisfies the `Robot` protocol; the control loop drives that robot."""
    from distgprl.sim.robot import Robot, UR5e
    from distgprl.sim.tasks.dcp import DCPSim

    built = []

    def factory(client, tool):
        robot = UR5e(client, tool)
        built.append(robot)
        return robot

    sim = DCPSim(robot_factory=factory)
    try:
        assert built and sim.robot is built[0] and sim.control.robot is built[0]
        assert isinstance(sim.robot, Robot) and sim.robot.tool is sim.tool
        assert sim.robot.name == "ur5e"
    finally:
        sim.close()
