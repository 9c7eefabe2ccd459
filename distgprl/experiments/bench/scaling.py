"""Sections 5a and 5b: adaptation compute vs the number of via-points and of obstacles."""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from distgprl.experiments.bench.baselines import BulletDistance
from distgprl.experiments.bench.pipeline import AdaptationPipeline
from distgprl.experiments.bench.sizes import BENCH_TASK, BenchSizes, run_spec
from distgprl.experiments.bench.timing import measure, measure_interleaved

__all__ = ["bench_obstacle_scaling", "bench_via_point_scaling", "random_boxes"]


def _scaled_skill(skill, n_via_points: int):
    """The task skill re-expressed with ``n_via_points`` evenly spaced via-points.

    Same fitted kernel; the via-points are the skill's own trajectory at the new times (what
    `fit_skill` gives up to the fit, without its seconds of marginal-likelihood optimisation).
    """
    from distgprl.skill.gp import GPSkill

    times = np.linspace(0.0, 1.0, n_via_points)
    via_points = skill.position(skill.via_points, times)
    via_points[0], via_points[-1] = skill.via_points[0], skill.via_points[-1]
    return GPSkill(
        skill.kernel,
        times,
        via_points,
        skill.prior_mean.copy(),
        skill.duration,
        skill.name,
        axis_scale=skill.axis_scale,
        axis_kernels=skill.axis_kernels,  # the zero-mean kernels do not depend on N
    )


def bench_via_point_scaling(sizes: BenchSizes, task: str = BENCH_TASK) -> list[dict[str, Any]]:
    """Section 5a: per-episode adaptation compute vs N via-points (3 windows of L = N // 3).

    Windows keep covering the interior, so the action (6 L) and observation sizes grow with N.
    """
    from distgprl.envs.adaptation import AdaptationEnv
    from distgprl.envs.tasks import load_task_skill
    from distgprl.experiments.runner import make_agent

    base = load_task_skill(task)
    rows = []
    for n in sizes.via_points:
        overrides = {"n_via_points": n, "window_size": n // 3}
        run = run_spec(task, env_overrides=overrides)
        env = AdaptationEnv(task, run.method, run.config.env, skill=_scaled_skill(base, n))
        try:
            model = make_agent(env, run)
            env.reset(seed=0)
            pipeline = AdaptationPipeline(env, model.actor)
            step, action = 1, pipeline.actions[1]

            def gp(pipeline=pipeline, step=step, action=action) -> None:
                pipeline.restart()
                pipeline.gp_conditioning(step, action)

            def edf_window(p: AdaptationPipeline = pipeline) -> object:
                return p.edf(1)

            timings = {
                "episode": measure(pipeline.episode, 3 * sizes.scaling_repeats, 3, 1),
                "edf_window": measure(edf_window, sizes.scaling_repeats, 3),
                "gp_window": measure(gp, sizes.scaling_repeats, 3, sizes.inner),
                "policy_window": measure(pipeline.policy, sizes.scaling_repeats, 3, sizes.inner),
            }
            rows.append(
                {
                    "n_via_points": n,
                    "window_size": n // 3,
                    "action_size": int(cast("tuple[int, ...]", env.action_space.shape)[0]),
                    "segment_samples": int(len(env.segment_tau(1))),
                    **{name: t.to_dict() for name, t in timings.items()},
                }
            )
        finally:
            env.close()
    return rows


def random_boxes(count: int, seed: int = 0) -> list:
    """``count`` axis-aligned and rotated boxes spread over the workspace (EDF primitives)."""
    from scipy.spatial.transform import Rotation

    from distgprl.safety.shapes import Box

    rng = np.random.default_rng(seed)
    return [
        Box(
            f"box{i}",
            rng.uniform([0.2, -0.5, 0.02], [0.8, 0.5, 0.5]),
            Rotation.from_euler("z", rng.uniform(0, np.pi)).as_matrix(),
            rng.uniform(0.01, 0.06, 3),
            True,
        )
        for i in range(count)
    ]


def bench_obstacle_scaling(env, model, sizes: BenchSizes) -> list[dict[str, Any]]:
    """Section 5b: per-episode adaptation compute and the EDF query vs number of boxes, with
    PyBullet closest points on the same points and boxes."""
    from distgprl.safety.edf import DistanceField

    rows = []
    for count in sizes.obstacles:
        shapes = random_boxes(count)
        field = DistanceField(shapes)
        pipeline = AdaptationPipeline(env, model.actor, field=field, shapes=shapes)
        bullet = BulletDistance(shapes)
        try:
            points = np.concatenate(
                (env.gamma[pipeline.layout.indices[1], :3], pipeline.tool_points)
            )

            def edf(p: AdaptationPipeline = pipeline) -> object:
                return p.edf(1)

            def pybullet(b: BulletDistance = bullet, x: np.ndarray = points) -> object:
                return b.distance(x)

            paired = measure_interleaved({"edf": edf, "pybullet": pybullet}, sizes.scaling_repeats)
            episode = measure(pipeline.episode, 3 * sizes.scaling_repeats, 3, 1)
        finally:
            bullet.close()
            pipeline.restart()
        rows.append(
            {
                "n_obstacles": count,
                "episode": episode.to_dict(),
                "edf_window": paired["edf"].to_dict(),
                "pybullet_window": paired["pybullet"].to_dict(),
                "edf_vs_pybullet": paired["pybullet"].median_us / paired["edf"].median_us,
            }
        )
    return rows
