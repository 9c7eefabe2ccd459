"""Task simulations: spawning, motion, collisions, clearance, success, determinism, render."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.safety.shapes import Box, Cylinder
from distgprl.sim.tasks import get_task
from distgprl.sim.tasks.base import TaskConfig, resample_to_control
from distgprl.skill.demos import load_demonstration


def hold(sim, steps):
    """``steps`` copies of the current TCP pose: the robot stands still."""
    return np.tile(sim.tcp_pose(), (steps, 1))


def straight_line(start, end, steps):
    return np.linspace(start, end, steps + 1)[1:]


def test_dcp_spawn_and_drift(dcp_sim):
    """The cube starts at nominal + offset and drifts at the drift velocity until touched."""
    scene = dcp_sim.scene
    tc = TaskConfig(object_offset=(0.12, -0.1), obstacle_offset=(0.05, 0.05))
    dcp_sim.reset(tc)
    start = np.asarray(scene.cube_start) + tc.object_offset
    assert np.allclose(dcp_sim.object_position()[:2], start, atol=1e-9)
    assert dcp_sim.object_position()[2] == pytest.approx(scene.cube_half, abs=1e-3)
    dcp_sim.execute(hold(dcp_sim, 25))
    expected = start + np.asarray(scene.drift_velocity) * 25 * dcp_sim.control_dt
    assert np.allclose(dcp_sim.object_position()[:2], expected, atol=1e-6)
    assert not dcp_sim.object_released


def test_dcp_obstacle_moves_as_specified(dcp_sim):
    """The obstacle cube follows its sinusoid; obstacle_shapes reports the current pose."""
    scene = dcp_sim.scene
    tc = TaskConfig(obstacle_offset=(0.04, -0.06))
    dcp_sim.reset(tc)
    for _ in range(3):
        dcp_sim.execute(hold(dcp_sim, 10))
        t = dcp_sim.time
        phase = 2 * np.pi * t / scene.obstacle_period + scene.obstacle_phase
        expected_x = scene.obstacle_centre[0] + 0.04 + scene.obstacle_amplitude * np.sin(phase)
        shapes = {s.name: s for s in dcp_sim.obstacle_shapes()}
        assert shapes["obstacle_cube"].dynamic
        assert shapes["obstacle_cube"].position[0] == pytest.approx(expected_x, abs=1e-9)
        assert shapes["obstacle_cube"].position[1] == pytest.approx(
            scene.obstacle_centre[1] - 0.06, abs=1e-9
        )
        position = dcp_sim.client.getBasePositionAndOrientation(dcp_sim.obstacle_body)[0]
        assert np.allclose(position, shapes["obstacle_cube"].position, atol=1e-6)
    assert all(isinstance(s, Box) for s in dcp_sim.obstacle_shapes())


def test_dbm_spawn_and_conveyor_motion(dbm_sim):
    """Both bars start at nominal + offset and ride the belt at belt_speed along +y."""
    scene = dbm_sim.scene
    tc = TaskConfig(object_offset=(0.0, 0.15), obstacle_offset=(0.0, -0.1))
    dbm_sim.reset(tc)
    assert dbm_sim.object_position()[1] == pytest.approx(scene.target_start_y + 0.15, abs=1e-9)
    other = [s for s in dbm_sim.obstacle_shapes() if s.name == "other_bar_base"][0]
    assert other.position[1] == pytest.approx(scene.other_start_y - 0.1, abs=1e-9)
    dbm_sim.execute(hold(dbm_sim, 25))
    travel = scene.belt_speed * 25 * dbm_sim.control_dt
    assert dbm_sim.object_position()[1] == pytest.approx(scene.target_start_y + 0.15 + travel)
    other = [s for s in dbm_sim.obstacle_shapes() if s.name == "other_bar_base"][0]
    assert other.position[1] == pytest.approx(scene.other_start_y - 0.1 + travel, abs=1e-9)
    rollers = [s for s in dbm_sim.obstacle_shapes() if isinstance(s, Cylinder)]
    assert len(rollers) == scene.roller_count and not any(r.dynamic for r in rollers)


@pytest.mark.parametrize("sim_name", ["dcp_sim", "dbm_sim"])
def test_objects_spawn_inside_their_ranges(sim_name, request):
    """For evaluation TCs the object starts within the task's offset range of its nominal start."""
    sim = request.getfixturevalue(sim_name)
    spec = get_task("dcp" if sim_name == "dcp_sim" else "dbm")
    sim.reset(spec.nominal_tc)
    nominal = sim.object_position()
    for tc in spec.evaluation_tcs(10):
        sim.reset(tc)
        offset = sim.object_position()[:2] - nominal[:2]
        assert np.allclose(offset, tc.object_offset, atol=1e-9)
        assert np.linalg.norm(offset) <= 0.2 + 1e-9


def test_clear_pass_is_not_a_collision(dcp_sim):
    """Holding the start pose never touches anything: no collision, positive clearance."""
    dcp_sim.reset(TaskConfig())
    result = dcp_sim.execute(hold(dcp_sim, 20))
    assert not result.collision
    assert result.min_clearance > 0.0
    assert result.ik_failures == 0 and result.steps == 20


def test_driving_into_the_table_is_a_collision(dcp_sim):
    """Lowering the shovel 3 cm into the table is detected, with clearance <= 0."""
    dcp_sim.reset(TaskConfig())
    start = dcp_sim.tcp_pose()
    low = start.copy()
    low[2] = -0.03
    result = dcp_sim.execute(straight_line(start, low, 40))
    assert result.collision
    assert result.min_clearance <= 0.0


def test_driving_into_the_wall_is_a_collision(dcp_sim):
    """Moving the blade through the wall is detected."""
    dcp_sim.reset(TaskConfig())
    start = dcp_sim.tcp_pose()
    above_wall = start.copy()
    above_wall[:3] = [0.80, -0.3, 0.10]
    result = dcp_sim.execute(straight_line(start, above_wall, 60))
    assert result.collision


def test_hook_touching_the_other_bar_is_a_collision(dbm_sim):
    """Lowering the hook onto the (moving) other bar is detected; the target bar is untouched."""
    dbm_sim.reset(TaskConfig())
    start = dbm_sim.tcp_pose()
    other = [s for s in dbm_sim.obstacle_shapes() if s.name == "other_bar_beam"][0]
    target = start.copy()
    target[:3] = other.position + [0.0, 0.05 + 0.04 * 2.0, -0.01]
    result = dbm_sim.execute(straight_line(start, target, 50))
    assert result.collision
    assert not dbm_sim.object_released


def test_dcp_success_on_hand_made_states(dcp_sim):
    """The cube counts as delivered only with its centre inside the goal rectangle."""
    dcp_sim.reset(TaskConfig())
    assert not dcp_sim.success()
    client, body = dcp_sim.client, dcp_sim.object_body
    goal = dcp_sim.goal_position()
    half = np.asarray(dcp_sim.scene.goal_half_extents)
    client.resetBasePositionAndOrientation(body, goal.tolist(), (0, 0, 0, 1))
    assert dcp_sim.success() and dcp_sim.task_progress() == 1.0
    just_out = goal + [half[0] + 0.01, 0.0, 0.0]
    client.resetBasePositionAndOrientation(body, just_out.tolist(), (0, 0, 0, 1))
    assert not dcp_sim.success() and 0.0 < dcp_sim.task_progress() < 1.0
    lifted = goal + [0.0, 0.0, 0.2]
    client.resetBasePositionAndOrientation(body, lifted.tolist(), (0, 0, 0, 1))
    assert not dcp_sim.success()


def test_dbm_success_on_hand_made_states(dbm_sim):
    """The bar counts as removed only when lifted by at least lift_height."""
    dbm_sim.reset(TaskConfig())
    assert not dbm_sim.success() and dbm_sim.task_progress() == pytest.approx(0.0, abs=0.01)
    position = dbm_sim.object_position()
    lift = dbm_sim.scene.lift_height
    client, body = dbm_sim.client, dbm_sim.object_body
    client.resetBasePositionAndOrientation(
        body, (position + [0, 0, lift / 2]).tolist(), (0, 0, 0, 1)
    )
    assert not dbm_sim.success() and dbm_sim.task_progress() == pytest.approx(0.5, abs=0.01)
    client.resetBasePositionAndOrientation(
        body, (position + [0, 0, lift + 0.01]).tolist(), (0, 0, 0, 1)
    )
    assert dbm_sim.success() and dbm_sim.task_progress() == 1.0


@pytest.mark.parametrize("name", ["dcp", "dbm"])
def test_nominal_demo_succeeds_without_collision(name, request):
    """The shipped demonstration, executed on the nominal TC, succeeds and never collides."""
    sim = request.getfixturevalue(f"{name}_sim")
    spec = get_task(name)
    demo = load_demonstration(spec.demo_path)
    assert demo.duration == pytest.approx(sim.demo_duration)
    sim.reset(spec.nominal_tc)
    poses = resample_to_control(demo.times, demo.poses, sim.control_dt)
    interaction_step = int(spec.interaction_time * len(poses))
    before = sim.execute(poses[:interaction_step])
    assert not sim.object_released  # no contact with the object before the interaction time
    after = sim.execute(poses[interaction_step:])
    assert sim.object_released
    assert sim.success()
    assert not before.collision and not after.collision
    assert min(before.min_clearance, after.min_clearance) > 0.005
    assert before.ik_failures + after.ik_failures == 0


@pytest.mark.parametrize("name", ["dcp", "dbm"])
def test_same_tc_same_trajectory_same_outcome(name, request):
    """Executing the same trajectory on the same TC is bit-identical, even after another TC."""
    sim = request.getfixturevalue(f"{name}_sim")
    spec = get_task(name)
    demo = load_demonstration(spec.demo_path)
    poses = resample_to_control(demo.times, demo.poses, sim.control_dt)
    tc, other_tc = spec.evaluation_tcs(2)

    def run(config):
        sim.reset(config)
        results = [sim.execute(poses[:40]), sim.execute(poses[40:])]
        state = np.concatenate([sim.joint_positions(), sim.object_position(), sim.tcp_pose()])
        return results, state.tobytes()

    first = run(tc)
    run(other_tc)
    second = run(tc)
    assert first == second


def test_segments_equal_one_call(dcp_sim):
    """Three consecutive segments give the same end state as one call (motion continues)."""
    spec = get_task("dcp")
    demo = load_demonstration(spec.demo_path)
    poses = resample_to_control(demo.times, demo.poses, dcp_sim.control_dt)
    dcp_sim.reset(spec.nominal_tc)
    whole = dcp_sim.execute(poses)
    end_whole = dcp_sim.object_position()
    dcp_sim.reset(spec.nominal_tc)
    parts = [dcp_sim.execute(chunk) for chunk in np.array_split(poses, 3)]
    assert np.allclose(dcp_sim.object_position(), end_whole, atol=1e-12)
    assert min(p.min_clearance for p in parts) == pytest.approx(whole.min_clearance)
    assert sum(p.steps for p in parts) == whole.steps
    assert dcp_sim.time == pytest.approx(whole.steps * dcp_sim.control_dt)


def test_observation_accessors_have_documented_shapes(dbm_sim):
    """tcp_pose (6,), joint_positions (6,), object/goal (3,), tool points (m, 3)."""
    dbm_sim.reset(TaskConfig())
    assert dbm_sim.tcp_pose().shape == (6,)
    assert np.allclose(dbm_sim.tcp_pose(), dbm_sim.scene.start_pose, atol=1e-6)
    assert dbm_sim.joint_positions().shape == (6,)
    assert dbm_sim.object_position().shape == (3,) and dbm_sim.goal_position().shape == (3,)
    points = dbm_sim.tool_points()
    assert points.ndim == 2 and points.shape[1] == 3 and 40 <= points.shape[0] <= 60
    assert np.linalg.norm(points.mean(axis=0) - dbm_sim.tcp_pose()[:3]) < 0.2


def test_render_gives_a_non_empty_image(dcp_sim):
    """The TinyRenderer returns an RGB uint8 image with visible content."""
    dcp_sim.reset(TaskConfig())
    image = dcp_sim.render_rgb(64, 48)
    assert image.shape == (48, 64, 3) and image.dtype == np.uint8
    assert image.std() > 5.0


@pytest.mark.parametrize("sim_name", ["dcp_sim", "dbm_sim"])
def test_predicted_obstacles_match_the_simulated_ones_at_that_time(sim_name, request):
    """obstacle_shapes(t) is where the moving obstacles actually are once the episode is at t."""
    sim = request.getfixturevalue(sim_name)
    sim.reset(get_task(sim_name.removesuffix("_sim")).evaluation_tcs(1)[0])
    steps = 30
    when = steps * sim.control_dt
    predicted = {s.name: s for s in sim.obstacle_shapes(when) if s.dynamic}
    assert predicted, "the scene has moving obstacles"
    hold = np.tile(sim.tcp_pose(), (steps, 1))
    sim.execute(hold)
    assert sim.time == pytest.approx(when)
    for shape in sim.obstacle_shapes():
        if shape.dynamic:
            np.testing.assert_allclose(predicted[shape.name].position, shape.position, atol=1e-9)
    moved = [s for s in sim.obstacle_shapes(0.0) if s.dynamic]
    assert any(not np.allclose(s.position, predicted[s.name].position) for s in moved)


@pytest.mark.parametrize("sim_name", ["dcp_sim", "dbm_sim"])
@pytest.mark.parametrize("when", [None, 0.0, 1.7])
def test_moving_obstacles_are_the_dynamic_part_of_the_obstacles(sim_name, when, request):
    sim = request.getfixturevalue(sim_name)
    sim.reset(get_task(sim_name.removesuffix("_sim")).evaluation_tcs(2)[1])
    expected = [s for s in sim.obstacle_shapes(when) if s.dynamic]
    moving = sim.moving_obstacle_shapes(when)
    assert [s.name for s in moving] == [s.name for s in expected]
    for a, b in zip(moving, expected, strict=True):
        assert a.dynamic
        np.testing.assert_array_equal(a.position, b.position)


def test_peak_joint_speed_is_the_largest_joint_target_finite_difference(dbm_sim):
    """As the hardware safety layer computes it: IK targets (nearest branch) differenced at
    the control period, starting from the previous target; maximum over joints and poses."""
    from distgprl.limits import SafetyLimits
    from distgprl.safety_layer.plan_check import check_plan
    from distgprl.sim.transforms import pose_to_matrix

    spec = get_task("dbm")
    demo = load_demonstration(spec.demo_path)
    poses = resample_to_control(demo.times, demo.poses, dbm_sim.control_dt)[:40]
    dbm_sim.reset(spec.nominal_tc)
    q = np.array(dbm_sim.start_joint_positions, dtype=float)
    joints = []
    for pose in poses:
        q = dbm_sim.robot.ik_nearest(pose_to_matrix(pose), q)
        joints.append(q)
    expected = np.abs(np.diff(np.vstack([dbm_sim.start_joint_positions, joints]), axis=0)).max()
    expected /= dbm_sim.control_dt
    result = dbm_sim.execute(poses)
    assert result.peak_joint_speed == pytest.approx(expected, rel=1e-12)
    assert 0.0 < result.peak_joint_speed
    # The hardware safety layer flags the same plan exactly above/below this speed.
    for factor, flagged in ((0.999, True), (1.001, False)):
        limits = SafetyLimits(max_joint_speed=factor * result.peak_joint_speed)
        check = check_plan(
            poses,
            dbm_sim.start_joint_positions,
            dbm_sim.robot,
            limits,
            dbm_sim.control_dt,
            force=True,
        )
        assert any(v.limit == "joint_speed" for v in check.violations) == flagged
