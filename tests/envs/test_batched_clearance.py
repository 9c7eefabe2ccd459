"""The observation's batched clearances (issue 49) against environment v5's per-point loop.

`TimedClearance` now answers all window poses with one query (the moving obstacles shifted
per point, `DistanceField.distance(..., dynamic_shift=...)`) and the tasks give the anchors at
all times at once; the v5 code is kept in `tests/envs/_reference_clearance.py`. Distances
equal the reference to 1e-12 m, gradients to 1e-9 away from ties between two shapes, and
whole episodes (every observation, reward and info value) to 1e-9.
"""

from __future__ import annotations

import numpy as np
import pytest
from _reference_clearance import ReferenceTimedClearance

from distgprl.config_types import EnvConfig
from distgprl.envs.via_point_env import AdaptationEnv

TASKS = ("dcp", "dbm")


@pytest.fixture(scope="module", params=TASKS)
def env(request):
    env = AdaptationEnv(request.param, "dist-gprl")
    yield env
    env.close()


def test_window_distances_equal_the_per_point_loop(env):
    """Every window of five evaluation TCs, plus 300 random points at random times in the
    scene: the reference's distances to 1e-12 m, its gradients to 1e-9 where no two shapes
    tie, and the anchors to 1e-12 m."""
    sim = env.sim
    rng = np.random.default_rng(0)
    for tc in env.spec_task.evaluation_tcs(5):
        env.reset(options={"tc": tc})
        reference = ReferenceTimedClearance(sim.obstacle_shapes(), "predicted")
        times = env.episode_start_time + env.skill.via_times * env.skill.duration
        np.testing.assert_allclose(
            env.moving_obstacle_anchors(),
            reference.anchors(times, sim.moving_obstacle_shapes),
            rtol=0,
            atol=1e-12,
        )
        for indices in env.layout.indices:
            points = env.window_plan.window_poses(indices)[:, :3]
            when = env.episode_start_time + env.skill.via_times[indices] * env.skill.duration
            expected = reference.distance(points, when, sim.moving_obstacle_shapes)
            got = env.window_distance(indices)
            np.testing.assert_allclose(got[0], expected[0], rtol=0, atol=1e-12)
            np.testing.assert_allclose(got[1], expected[1], rtol=0, atol=1e-9)
        centre = env.skill.via_points[:, :3].mean(axis=0)
        points = centre + rng.uniform(-0.4, 0.4, (300, 3))
        when = rng.uniform(0.0, env.skill.duration, 300)
        expected_d, expected_g = reference.distance(points, when, sim.moving_obstacle_shapes)
        got_d, got_g = env.clearance.distance(
            points, when, sim.moving_obstacle_shapes, sim.moving_obstacle_anchors_at
        )
        np.testing.assert_allclose(got_d, expected_d, rtol=0, atol=1e-12)
        gap = _second_nearest_gap(sim, points, when)
        untied = gap > 1e-9
        assert untied.mean() > 0.95
        np.testing.assert_allclose(got_g[untied], expected_g[untied], rtol=0, atol=1e-9)


def _second_nearest_gap(sim, points, times) -> np.ndarray:
    """Per point, the second-nearest shape's distance minus the nearest's (obstacles at the
    point's time), from fresh fields: where it is ~0 the gradient may follow either shape."""
    from distgprl.safety.edf import DistanceField

    gaps = np.empty(len(points))
    for i, (point, when) in enumerate(zip(points, times, strict=True)):
        per_shape = DistanceField(sim.obstacle_shapes(float(when))).distance_per_shape(point)[0]
        ordered = np.sort(per_shape)
        gaps[i] = ordered[1] - ordered[0] if len(ordered) > 1 else np.inf
    return gaps


def test_anchors_at_equal_the_shapes_positions(env):
    """The tasks' vectorised anchors equal the first moving shape's position at each time."""
    sim = env.sim
    env.reset(options={"tc": env.spec_task.evaluation_tcs(3)[2]})
    times = np.linspace(0.0, 2.0 * env.skill.duration, 41)
    expected = np.stack([sim.moving_obstacle_shapes(float(t))[0].position for t in times])
    np.testing.assert_allclose(sim.moving_obstacle_anchors_at(times), expected, rtol=0, atol=1e-12)


class _V5Clearance(ReferenceTimedClearance):
    """The reference behind the current call signature (the anchors callable is ignored)."""

    def distance(self, points, times, moving_shapes_at, anchors_at=None):
        return super().distance(points, times, moving_shapes_at)

    def anchors(self, times, moving_shapes_at, anchors_at=None):
        return super().anchors(times, moving_shapes_at)


@pytest.mark.parametrize("task", TASKS)
@pytest.mark.parametrize("timing", ["predicted", "current"])
def test_episodes_equal_the_v5_observation_and_step(task, timing):
    """The same episodes (three evaluation TCs, the same random actions) with the batched
    clearances and with v5's loop swapped in: every observation, reward and info value to
    1e-9 (r_sd now reads distances without gradients: the same values)."""
    config = EnvConfig(clearance_timing=timing)
    new, old = AdaptationEnv(task, "dist-gprl", config), AdaptationEnv(task, "dist-gprl", config)
    try:
        old.clearance = _V5Clearance(old.sim.obstacle_shapes(), timing)
        old.field = old.clearance.field
        rng = np.random.default_rng(1)
        for tc in new.spec_task.evaluation_tcs(3):
            observations = [new.reset(options={"tc": tc})[0], old.reset(options={"tc": tc})[0]]
            done = False
            while not done:
                for key in ("state", "aux"):
                    np.testing.assert_allclose(
                        observations[0][key], observations[1][key], rtol=1e-6, atol=1e-9
                    )
                action = rng.uniform(-1, 1, new.action_space.shape).astype(np.float32)
                a, b = new.step(action), old.step(action)
                observations = [a[0], b[0]]
                assert a[1] == pytest.approx(b[1], rel=1e-9, abs=1e-9)
                assert a[2] == b[2]
                for key, value in a[4].items():
                    if isinstance(value, float):
                        assert value == pytest.approx(b[4][key], rel=1e-9, abs=1e-9), key
                done = a[2] or a[3]
    finally:
        new.close()
        old.close()
