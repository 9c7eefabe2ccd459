"""The adaptation MDP on the real task simulations (small, deterministic fixtures)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import distgprl.envs  # noqa: F401  (registers the env ids)
from distgprl.config_types import ENVIRONMENT_VERSION, EnvConfig
from distgprl.envs.via_point_env import REWARD_TERMS, AdaptationEnv
from distgprl.safety.edf import DistanceField
from distgprl.safety.hap_filter import MovingObstacleFilter
from distgprl.sim.tasks.base import TaskConfig
from distgprl.skill.operator import axis_operator


@pytest.fixture(scope="module")
def dcp_env():
    env = AdaptationEnv("dcp", "dist-gprl")
    yield env
    env.close()


def rollout(env, tc, actions):
    """Step through ``actions`` until the episode ends (v5: possibly early, at a collision)."""
    obs, _ = env.reset(options={"tc": tc})
    records = []
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        records.append((obs, reward, terminated, info))
        if terminated:
            break
    return records


def test_passes_gymnasium_check_env():
    env = gym.make(f"DistGPRL-DCP-v{ENVIRONMENT_VERSION}", method="dist-gprl").unwrapped
    check_env(env, skip_render_check=True)
    env.close()


def test_a_collision_stops_execution_and_ends_the_episode_without_success():
    """v5: pushing every via-point into the table collides in the first segment; execution
    stops at the colliding control period (fewer poses than the segment), the episode ends
    at step 0 with success False, the collision penalty paid, and a further step raises."""
    env = AdaptationEnv("dcp", "dist-gprl-nocov")
    executed = []
    execute = env.sim.execute

    def spy(poses, **kwargs):
        result = execute(poses, **kwargs)
        executed.append((len(poses), result.steps, result.collision, result.stopped))
        return result

    env.sim.execute = spy
    n = env.action_space.shape[0]
    down = np.zeros((n // 6, 6))
    down[:, 2] = -1.0
    env.reset(options={"tc": env.spec_task.nominal_tc})
    _, reward, terminated, _, info = env.step(down.ravel())
    assert terminated and info["collision"] and not info["success"]
    assert info["stopped_at_step"] == 0
    assert info["r_collision"] == -env.config.collision_penalty and info["r_success"] == 0.0
    assert info["min_clearance"] == 0.0 and info["min_signed_clearance"] <= 0.0
    poses, steps, collision, stopped = executed[-1]
    assert collision and stopped and steps < poses
    with pytest.raises(RuntimeError, match="episode is over"):
        env.step(down.ravel())
    env.close()


def test_without_protective_stop_the_episode_runs_on_through_a_collision():
    """``collision_ends_episode=False`` (v4 semantics): the same colliding actions run all
    three steps, and success is completion regardless of the collision."""
    env = AdaptationEnv("dcp", "dist-gprl-nocov", EnvConfig(collision_ends_episode=False))
    n = env.action_space.shape[0]
    down = np.zeros((n // 6, 6))
    down[:, 2] = -1.0
    env.reset(options={"tc": env.spec_task.nominal_tc})
    terminated, steps = False, 0
    while not terminated:
        _, _, terminated, _, info = env.step(down.ravel())
        steps += 1
    assert steps == 3 and info["collision"] and info["stopped_at_step"] == -1
    assert info["success"] == info["completed"]
    env.close()


def test_episode_is_three_steps_and_reward_terms_sum_to_reward(dcp_env):
    rng = np.random.default_rng(0)
    tc = dcp_env.spec_task.evaluation_tcs(3)[1]
    actions = 0.2 * rng.uniform(-1, 1, size=(3, dcp_env.action_space.shape[0]))
    records = rollout(dcp_env, tc, actions)
    assert [r[2] for r in records] == [False, False, True]
    for _, reward, _, info in records:
        assert reward == pytest.approx(sum(info[k] for k in REWARD_TERMS), abs=1e-9)
    final = records[-1][3]
    for key in ("success", "collision", "min_clearance", "kinematic_retention"):
        assert key in final
    # The episode's peak commanded joint speed is the largest of its executed chunks'.
    assert final["peak_joint_speed"] > 0
    assert len(final["adaptation_time_s"]) == 3


REWARD_METHODS = ["dist-gprl", "gprl", "gprl-h", "dist-gprl-nocov", "dist-gprl-global", "demo"]


def clearance_penalty(sim, config: EnvConfig) -> float:
    """Eq. safety_reward recomputed from public pieces: -beta sum_{d_i < d_min} 1/(d_i+eps)
    over the tool points, d from a fresh field of the obstacles where they are now."""
    d, _ = DistanceField(sim.obstacle_shapes()).distance(sim.tool_points())
    close = d < config.sd_d_min
    return -config.sd_beta * float(np.sum(1.0 / (np.maximum(d[close], 0.0) + config.sd_epsilon)))


def spy_on_segments(env, monkeypatch) -> list[tuple[bool, float]]:
    """Wrap ``env.sim.execute``: per executed chunk, its collision flag and the clearance
    penalty recomputed independently right after it."""
    chunks: list[tuple[bool, float]] = []
    execute = env.sim.execute

    def spy(poses, **kwargs):
        result = execute(poses, **kwargs)
        chunks.append((bool(result.collision), clearance_penalty(env.sim, env.config)))
        return result

    monkeypatch.setattr(env.sim, "execute", spy)
    return chunks


@pytest.mark.parametrize("method", REWARD_METHODS)
def test_reward_terms_have_their_specified_values(method, monkeypatch):
    """Each term of ``info`` has the value the env docstring specifies and they sum to the
    reward, on three DCP episodes: the unadapted nominal episode (succeeds, the shovel skims
    the table), every via-point pushed down (into the table: collisions) and random
    actions on an evaluation TC. r_progress is the weighted progress change; r_success is
    the bonus at the last step iff success; r_collision is -penalty iff that step's segment
    collided; r_sd <= 0 is the clearance penalty summed over the step's chunks (0 without
    distance rewards); |r_ga| <= lambda_ga (0 without distance rewards); r_signature in
    (0, weight] for GPRL only."""
    env = AdaptationEnv("dcp", method)
    config, spec = env.config, env.method
    chunks = spy_on_segments(env, monkeypatch)
    n = env.action_space.shape[0]
    down = np.zeros((n // 6, 6))
    down[:, 2] = -1.0
    episodes = {
        "nominal": (env.spec_task.nominal_tc, np.zeros((3, n))),
        "down": (env.spec_task.nominal_tc, np.tile(down.ravel(), (3, 1))),
        "random": (
            env.spec_task.evaluation_tcs(3)[0],  # v6: the unadapted demo collides on it
            np.random.default_rng(0).uniform(-1, 1, size=(3, n)),
        ),
    }
    seen = {"success": [], "collision": [], "r_sd": [], "r_ga": []}
    for name, (tc, actions) in episodes.items():
        env.reset(options={"tc": tc})
        progress = env.sim.task_progress()
        step_collisions = []
        for k, action in enumerate(actions):
            first_chunk = len(chunks)
            _, reward, terminated, _, info = env.step(action)
            step_chunks = chunks[first_chunk:]
            where = f"{method} {name} step {k}"
            assert reward == pytest.approx(sum(info[t] for t in REWARD_TERMS), abs=1e-9), where
            now = env.sim.task_progress()
            assert info["r_progress"] == pytest.approx(
                config.progress_weight * (now - progress), abs=1e-12
            ), where
            progress = now
            expected_success = config.success_bonus * info["success"] if terminated else 0.0
            assert info["r_success"] == expected_success, where
            collided = any(c for c, _ in step_chunks)
            step_collisions.append(collided)
            assert info["r_collision"] == (-config.collision_penalty if collided else 0.0), where
            assert info["r_sd"] <= 0.0, where
            if spec.distance_rewards:
                expected_sd = sum(p for _, p in step_chunks)
                assert info["r_sd"] == pytest.approx(expected_sd, rel=1e-9, abs=1e-12), where
                assert abs(info["r_ga"]) <= config.lambda_ga + 1e-9, where
            else:
                assert info["r_sd"] == 0.0 and info["r_ga"] == 0.0, where
            if spec.signature_reward:
                assert 0.0 < info["r_signature"] <= config.signature_weight + 1e-12, where
            else:
                assert info["r_signature"] == 0.0, where
            seen["r_sd"].append(info["r_sd"])
            seen["r_ga"].append(info["r_ga"])
            if terminated:  # v5: a collision ends the episode at its step
                assert k == 2 or (collided and info["stopped_at_step"] == k), where
                break
        assert terminated
        assert info["collision"] == any(step_collisions), f"{method} {name}"
        seen["success"].append(info["success"])
        seen["collision"].append(info["collision"])
    env.close()
    # The episodes exercise both branches of the indicator terms.
    assert any(seen["success"]) and not all(seen["success"]), seen["success"]
    assert any(seen["collision"]) and not all(seen["collision"]), seen["collision"]
    if spec.distance_rewards:  # the shovel passes within d_min of the table, the actions move
        assert min(seen["r_sd"]) < 0.0 and any(g != 0.0 for g in seen["r_ga"]), seen


def test_safety_reward_matches_an_independent_recomputation_after_the_segment():
    """With one r_sd sample per segment, r_sd is exactly Eq. safety_reward for the tool
    points and obstacles after the step, recomputed from sim.obstacle_shapes() and
    sim.tool_points(); the nominal DCP episode brings the shovel within d_min."""
    config = EnvConfig(sd_samples_per_segment=1)
    env = AdaptationEnv("dcp", "dist-gprl", config)
    env.reset(options={"tc": env.spec_task.nominal_tc})
    values = []
    for _ in range(3):
        _, _, _, _, info = env.step(np.zeros(30))
        expected = clearance_penalty(env.sim, config)
        assert info["r_sd"] == pytest.approx(expected, rel=1e-12, abs=1e-15)
        values.append(info["r_sd"])
    env.close()
    assert min(values) < 0.0, values  # not only the trivial 0 == 0


def test_window_update_applies_the_covariance_transform(dcp_env):
    tc = dcp_env.spec_task.nominal_tc
    dcp_env.reset(options={"tc": tc})
    before = dcp_env.gamma.copy()
    action = np.random.default_rng(1).uniform(-1, 1, size=30)
    dcp_env.step(action)
    window = dcp_env.layout.indices[0]
    scaled = action.reshape(5, 6) * dcp_env.layout.scale
    # v6: per axis a, S_W,a from K_a = the covariance of the axis's zero-mean GP (Eq. 1)
    index = np.ix_(window, window)
    expected = np.stack(
        [
            axis_operator(dcp_env.skill.via_times, kernel, 1e-2)[index] @ scaled[:, a]
            for a, kernel in enumerate(dcp_env.skill.axis_kernels)
        ],
        axis=1,
    )
    np.testing.assert_allclose(dcp_env.gamma[window] - before[window], expected, atol=1e-12)
    untouched = np.setdiff1d(np.arange(15), window)
    np.testing.assert_array_equal(dcp_env.gamma[untouched], before[untouched])


def test_nocov_applies_the_raw_scaled_action():
    env = AdaptationEnv("dcp", "dist-gprl-nocov")
    env.reset(options={"tc": env.spec_task.nominal_tc})
    before = env.gamma.copy()
    action = np.random.default_rng(2).uniform(-1, 1, size=30)
    env.step(action)
    window = env.layout.indices[0]
    np.testing.assert_allclose(
        env.gamma[window] - before[window], action.reshape(5, 6) * env.layout.scale
    )
    env.close()


def test_same_tc_and_actions_give_identical_outcomes(dcp_env):
    tc = dcp_env.spec_task.evaluation_tcs(5)[4]
    actions = np.random.default_rng(3).uniform(-1, 1, size=(3, 30))
    first = rollout(dcp_env, tc, actions)
    second = rollout(dcp_env, tc, actions)
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(a[0]["state"], b[0]["state"])
        assert a[1] == b[1]


def test_demo_method_ignores_actions():
    env = AdaptationEnv("dcp", "demo")
    env.reset(options={"tc": env.spec_task.nominal_tc})
    before = env.gamma.copy()
    env.step(np.ones(30))
    np.testing.assert_array_equal(env.gamma, before)
    env.close()


def test_distance_terms_only_for_methods_with_distance_rewards():
    env = AdaptationEnv("dcp", "gprl-h")
    tc = env.spec_task.evaluation_tcs(2)[0]
    records = rollout(env, tc, np.full((3, 30), 0.5))
    assert all(r[3]["r_sd"] == 0.0 and r[3]["r_ga"] == 0.0 for r in records)
    env.close()


def test_gradient_alignment_reward_is_positive_for_moves_along_the_gradient(dcp_env):
    dcp_env.reset(options={"tc": dcp_env.spec_task.nominal_tc})
    window = dcp_env.layout.indices[0]
    _, gradient = dcp_env.window_distance(window)
    # Raw action whose S_W-transformed position part points along the EDF gradient.
    target = np.zeros((5, 6))
    target[:, :3] = gradient * 0.02
    operators = dcp_env.layout.operators[0]  # (6, L, L): one S_W per axis (v5)
    raw = np.stack([np.linalg.solve(operators[a], target[:, a]) for a in range(6)], axis=1)
    raw = np.clip(raw / dcp_env.layout.scale, -1, 1).ravel()
    _, _, _, _, info = dcp_env.step(raw)
    assert info["r_ga"] > 0


def test_global_method_observes_and_adapts_all_interior_via_points():
    env = AdaptationEnv("dcp", "dist-gprl-global")
    assert env.action_space.shape == (78,)
    assert env.observation_space["state"].shape == (78 + 13 + 7,)
    env.close()


def test_gprl_holds_the_tc_via_point():
    env = AdaptationEnv("dcp", "gprl")
    tc = env.spec_task.evaluation_tcs(1)[0]
    env.reset(options={"tc": tc})
    held = env.gamma[env.interaction_index].copy()
    for _ in range(3):
        env.step(np.ones(78))
    np.testing.assert_array_equal(env.gamma[env.interaction_index], held)
    env.close()


def test_dbm_env_runs_an_episode():
    env = AdaptationEnv("dbm", "dist-gprl")
    records = rollout(env, env.spec_task.evaluation_tcs(1)[0], np.zeros((3, 30)))
    assert records[-1][2]
    env.close()


@pytest.mark.parametrize("task", ["dcp", "dbm"])
def test_observations_stay_well_scaled_under_saturated_actions(task):
    """Standardised inputs stay O(1) even when actions change axes the demo keeps constant."""
    env = AdaptationEnv(task, "dist-gprl")
    rng = np.random.default_rng(0)
    for tc in env.spec_task.evaluation_tcs(3):
        obs, _ = env.reset(options={"tc": tc})
        terminated = False
        while not terminated:  # v5: a collision may end the episode early
            assert np.abs(obs["state"]).max() < 10.0
            obs, _, terminated, _, _ = env.step(rng.choice([-1.0, 1.0], size=30))
    env.close()


@pytest.mark.parametrize("timing", ["predicted", "current"])
def test_window_clearances_use_obstacles_at_the_via_points_time(timing):
    """v2: clearance j is against the obstacles when the trajectory reaches via-point j."""
    env = AdaptationEnv("dcp", "dist-gprl", EnvConfig(clearance_timing=timing))
    obs, _ = env.reset(options={"tc": env.spec_task.evaluation_tcs(1)[0]})
    window = env.layout.indices[0]
    points = env.gamma[window, :3]
    expected = []
    for j, index in enumerate(window):
        when = env.skill.via_times[index] * env.skill.duration if timing == "predicted" else None
        expected.append(DistanceField(env.sim.obstacle_shapes(when)).distance(points[j : j + 1])[0])
    clip = env.config.clearance_clip
    observed = obs["state"][30:35] * env.config.clearance_scale
    np.testing.assert_allclose(observed, np.clip(np.concatenate(expected), -clip, clip), atol=1e-6)
    env.close()


def test_predicted_and_current_clearances_differ_while_the_obstacle_moves():
    # DBM: the other bar 11 cm behind the target; the belt carries it under the approach.
    tc = TaskConfig(object_offset=(0.0, 0.0), obstacle_offset=(0.0, 0.05))
    observed = {}
    for timing in ("predicted", "current"):
        env = AdaptationEnv("dbm", "dist-gprl", EnvConfig(clearance_timing=timing))
        observed[timing] = env.reset(options={"tc": tc})[0]["state"][30:35]
        env.close()
    assert not np.allclose(observed["predicted"], observed["current"], atol=1e-2)
    # The approach via-points come closer to the bar that will be there.
    assert observed["predicted"][2:].sum() < observed["current"][2:].sum()


def test_unknown_clearance_timing_is_rejected():
    with pytest.raises(ValueError, match="clearance_timing"):
        AdaptationEnv("dcp", "dist-gprl", EnvConfig(clearance_timing="later"))


def test_relative_positions_are_observed_in_units_of_their_scale(dcp_env):
    obs, _ = dcp_env.reset(options={"tc": dcp_env.spec_task.nominal_tc})
    tcp = dcp_env.sim.tcp_pose()[:3]
    scale = dcp_env.config.relative_position_scale
    np.testing.assert_allclose(
        obs["state"][35:38], (dcp_env.sim.object_position() - tcp) / scale, atol=1e-5
    )
    np.testing.assert_allclose(
        obs["state"][38:41], (dcp_env.sim.goal_position() - tcp) / scale, atol=1e-5
    )


@pytest.mark.parametrize("step", [0, 1])
def test_r_ga_uses_the_gradient_at_the_via_points_before_the_update(step, monkeypatch):
    """Eq. grad_alignment_reward: r_ga = lambda_ga mean_j cos(Delta Gamma_j, grad d(v_j)) with
    v_j the window's via-points *before* the step's update (v4). The field is replaced by one
    whose gradient turns with position (radial about a point below the window), so the
    gradients at the updated via-points differ and the test tells the two apart."""
    env = AdaptationEnv("dcp", "dist-gprl")
    rng = np.random.default_rng(3)
    env.reset(options={"tc": env.spec_task.nominal_tc})
    for _ in range(step):
        env.step(rng.uniform(-1, 1, env.action_space.shape))
    window = env.layout.indices[step]
    centre = env.gamma[window, :3].mean(axis=0) - np.array([0.0, 0.0, 0.05])

    def radial_field(indices):
        offset = env.gamma[indices, :3] - centre
        norm = np.linalg.norm(offset, axis=1)
        return norm, offset / norm[:, None]

    monkeypatch.setattr(env, "window_distance", radial_field)
    before = radial_field(window)[1]
    raw = rng.uniform(-1, 1, env.action_space.shape)
    delta = env.layout.delta(step, raw)
    _, _, _, _, info = env.step(raw)
    after = radial_field(window)[1]
    cosines = np.sum(delta[:, :3] * before, axis=1) / (
        np.linalg.norm(delta[:, :3], axis=1) * np.linalg.norm(before, axis=1)
    )
    assert info["r_ga"] == pytest.approx(env.config.lambda_ga * cosines.mean(), abs=1e-12)
    stale = np.sum(delta[:, :3] * after, axis=1) / np.linalg.norm(delta[:, :3], axis=1)
    assert abs(env.config.lambda_ga * stale.mean() - info["r_ga"]) > 1e-3
    env.close()


@pytest.mark.parametrize("timing", ["predicted", "current"])
def test_aux_carries_the_moving_obstacles_anchor_at_each_via_point_time(timing):
    """With the HAP prior, aux ends with the moving obstacles' anchor (their first box's
    centre) at every via-point time (``predicted``) or now (``current``); without it, aux is
    Gamma and the one-hot only."""
    env = AdaptationEnv("dbm", "dist-gprl", EnvConfig(clearance_timing=timing))
    observation, _ = env.reset(options={"tc": env.spec_task.nominal_tc})
    n = env.config.n_via_points
    anchors = observation["aux"][n * 6 + env.layout.n_steps :].reshape(n, 3)
    sim = env.sim
    if timing == "predicted":
        times = env.episode_start_time + env.skill.via_times * env.skill.duration
        expected = [sim.moving_obstacle_shapes(float(t))[0].position for t in times]
    else:
        expected = [sim.moving_obstacle_shapes()[0].position] * n
    np.testing.assert_allclose(anchors, np.array(expected), atol=1e-6)
    if timing == "predicted":  # the belt moves the other bar between via-point times
        assert np.ptp(anchors[:, :2], axis=0).max() > 0.01
    env.close()
    plain = AdaptationEnv("dbm", "gprl-d")
    assert plain.observation_space["aux"].shape == (n * 6 + plain.layout.n_steps,)
    plain.close()


def test_moving_obstacle_filter_blocks_poses_whose_tool_would_touch_the_obstacle(dcp_env):
    """A TCP position right at the moving cube is blocked, one far away is not, and the tool
    box covers every tool point at the current pose."""
    dcp_env.reset(options={"tc": dcp_env.spec_task.nominal_tc})
    moving = dcp_env.moving_obstacle_filter()
    anchor = MovingObstacleFilter.anchor(dcp_env.sim.moving_obstacle_shapes())
    assert moving.blocked(anchor[None, None], anchor[None])[0, 0]
    far = anchor + np.array([0.0, 0.0, 1.0])
    assert not moving.blocked(far[None, None], anchor[None])[0, 0]
    # The tool itself, at the current pose, lies inside the tool box the filter grew by.
    tcp = dcp_env.sim.robot.tcp_transform()
    centre, half = dcp_env.tool_box()
    world = dcp_env.sim.robot.tool_points() - tcp[:3, 3]
    assert np.all(np.abs(world - centre) <= half + 0.02)  # current orientation ~ the demo's


@pytest.mark.parametrize("tool", ["SHOVEL", "HOOK"])
def test_r_sd_charges_the_whole_tool_at_contact_one_collision_per_segment(tool):
    """Environment v7: beta = eps / (instants x tool points), so the whole tool held at
    contact (d = 0) for a segment costs exactly the collision penalty, and at d_min a quarter
    of it (v6 charged each of the tool's points that much)."""
    from distgprl.sim import robot

    config = EnvConfig()
    points = sum(getattr(robot, tool).surface_points_per_box)
    per_segment = config.sd_samples_per_segment * points
    at_contact = config.sd_beta * per_segment / config.sd_epsilon
    assert at_contact == pytest.approx(config.collision_penalty, rel=1e-12)
    at_margin = config.sd_beta * per_segment / (config.sd_d_min + config.sd_epsilon)
    assert at_margin == pytest.approx(0.25 * config.collision_penalty, rel=1e-12)


V7_EPISODE_TCS = 3


def _v7_env(task: str, monkeypatch):
    """The paper preset's dist-gprl env with v7's control loop and v7's NumPy distance field
    (`tests/sim/_reference_control.py`, `tests/safety/_reference_edf.py`) in place of the
    planned loop and the compiled field of protocol v8 rule 6 (issue 66)."""
    from pathlib import Path

    tests = Path(__file__).resolve().parents[1]
    monkeypatch.syspath_prepend(str(tests / "sim"))
    monkeypatch.syspath_prepend(str(tests / "safety"))
    from _reference_control import reference_run
    from _reference_edf import reference_distance

    from distgprl.experiments.bench.sizes import run_spec
    from distgprl.experiments.factories import make_env

    env = make_env(run_spec(task, "dist-gprl"))
    sim, field = env.unwrapped.sim, env.unwrapped.field

    def v7_execute(poses, stop_on_collision=False, clearance_below=None):
        return reference_run(sim, poses, stop_on_collision)  # v7 queried at the cutoff

    monkeypatch.setattr(sim, "execute", v7_execute)
    monkeypatch.setattr(
        field,
        "distance",
        lambda points, dynamic_shift=None: reference_distance(field, points, dynamic_shift),
    )
    monkeypatch.setattr(field, "clearance", lambda points: reference_distance(field, points)[0])
    return env


@pytest.mark.parametrize("task", ["dcp", "dbm"])
def test_v8_speed_work_keeps_v7s_episodes(task, monkeypatch):
    """On fixed evaluation TCs with fixed random actions, the env with v8's speed work
    (issue 66: the planned control loop, the compiled distance field, the tool points, the
    clearance queries culled at the episode's minimum) plays v7's episodes: the same steps,
    success, collision, stop, min clearance and peak joint speed (tolerance zero: the
    control loop is bit-identical, tests/sim/test_control_equivalence.py, and the field
    does not act on the physics), rewards and their terms within 1e-9 and the state within
    1e-6 (the field's values differ by the rounding of its local coordinates, ≤ 1e-15 m,
    tests/safety/test_edf.py; r_sd's 1 / (d + eps) and the float32 state amplify that far
    below these bounds)."""
    from distgprl.experiments.bench.sizes import run_spec
    from distgprl.experiments.factories import make_env

    new, old = make_env(run_spec(task, "dist-gprl")), _v7_env(task, monkeypatch)
    rng = np.random.default_rng(66)
    exact = (
        "success",
        "completed",
        "collision",
        "stopped_at_step",
        "min_clearance",
        "min_signed_clearance",
        "peak_joint_speed",
    )
    try:
        for tc in new.unwrapped.spec_task.evaluation_tcs(V7_EPISODE_TCS):
            obs_new, _ = new.reset(options={"tc": tc})
            obs_old, _ = old.reset(options={"tc": tc})
            done = False
            while not done:
                np.testing.assert_allclose(obs_new["state"], obs_old["state"], atol=1e-6)
                np.testing.assert_allclose(obs_new["aux"], obs_old["aux"], atol=1e-6)
                action = rng.uniform(-1.0, 1.0, new.action_space.shape).astype(np.float32)
                obs_new, r_new, term_new, _, info_new = new.step(action)
                obs_old, r_old, term_old, _, info_old = old.step(action)
                assert term_new == term_old
                assert abs(r_new - r_old) <= 1e-9
                for key in REWARD_TERMS:
                    assert abs(info_new[key] - info_old[key]) <= 1e-9, key
                for key in exact:
                    assert info_new.get(key) == info_old.get(key), key
                done = term_new
    finally:
        new.close()
        old.close()
