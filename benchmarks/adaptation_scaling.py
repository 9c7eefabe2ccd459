"""Adaptation compute against the number of via-points and of obstacles (a study beside the
paper's §V figures, which `distgprl bench` measures at the paper's sizes).

    python benchmarks/adaptation_scaling.py [--size full|quick|tiny] [--out PATH]

1. Via-points: per-episode adaptation compute and its parts per window (EDF query, GP
   conditioning, policy) for N via-points in three windows of N // 3 (the action and the
   observation grow with N), the task's fitted kernel kept.
2. Obstacles: per-episode adaptation compute and the EDF query against PyBullet's closest
   points on the same points, for k random boxes.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np

from distgprl.experiments.bench.baselines import BulletDistance
from distgprl.experiments.bench.pipeline import AdaptationPipeline
from distgprl.experiments.bench.sizes import BENCH_TASK, run_spec
from distgprl.experiments.bench.timing import measure, measure_interleaved

SIZES: dict[str, dict[str, Any]] = {
    "full": {"via_points": (15, 30, 45, 60), "obstacles": (1, 2, 4, 8, 16, 32), "repeats": 60,
             "inner": 10},
    "quick": {"via_points": (15, 60), "obstacles": (1, 8, 32), "repeats": 10, "inner": 5},
    "tiny": {"via_points": (15, 30), "obstacles": (1, 4), "repeats": 2, "inner": 2},
}  # fmt: skip
"""The points of each curve, the samples per point and the calls per sample of the
microsecond operations (GP conditioning, policy), by size (``tiny``: the tests')."""


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


def bench_via_point_scaling(
    via_points: Sequence[int], repeats: int, inner: int, task: str = BENCH_TASK
) -> list[dict[str, Any]]:
    """Per-episode adaptation compute vs N via-points (3 windows of L = N // 3), ``repeats``
    samples per point (of ``inner`` calls for the GP conditioning and the policy).

    Windows keep covering the interior, so the action (6 L) and observation sizes grow with N.
    """
    from distgprl.envs.tasks import load_task_skill
    from distgprl.envs.via_point_env import AdaptationEnv
    from distgprl.experiments.factories import make_agent

    base = load_task_skill(task)
    rows = []
    for n in via_points:
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
                "episode": measure(pipeline.episode, 3 * repeats, 3, 1),
                "edf_window": measure(edf_window, repeats, 3),
                "gp_window": measure(gp, repeats, 3, inner),
                "policy_window": measure(pipeline.policy, repeats, 3, inner),
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


def bench_obstacle_scaling(
    obstacles: Sequence[int], repeats: int, task: str = BENCH_TASK
) -> list[dict[str, Any]]:
    """Per-episode adaptation compute and the EDF query vs number of boxes, with PyBullet
    closest points on the same points and boxes, ``repeats`` samples per point."""
    from distgprl.experiments.factories import make_agent, make_env

    run = run_spec(task)
    env = make_env(run)
    try:
        model = make_agent(env, run)
        env.reset(seed=0)
        return _obstacle_rows(env, model, obstacles, repeats)
    finally:
        env.close()


def _obstacle_rows(env, model, obstacles: Sequence[int], repeats: int) -> list[dict[str, Any]]:
    """The rows of `bench_obstacle_scaling` on a reset environment and its agent."""
    from distgprl.safety.edf import DistanceField

    rows = []
    for count in obstacles:
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

            paired = measure_interleaved({"edf": edf, "pybullet": pybullet}, repeats)
            episode = measure(pipeline.episode, 3 * repeats, 3, 1)
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


def run_study(size: str) -> dict[str, Any]:
    """Both curves at ``size`` (a key of `SIZES`), one torch thread as in training."""
    import torch

    sizes = SIZES[size]
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return {
            "size": size,
            "via_points": bench_via_point_scaling(
                sizes["via_points"], sizes["repeats"], sizes["inner"]
            ),
            "obstacles": bench_obstacle_scaling(sizes["obstacles"], sizes["repeats"]),
        }
    finally:
        torch.set_num_threads(threads)


def describe(document: dict[str, Any]) -> str:
    """The two curves as text: medians in ms."""
    lines = ["via-points: per episode / EDF, GP, policy per window (ms)"]
    for row in document["via_points"]:
        parts = [row[key]["median_us"] / 1e3 for key in ("episode", "edf_window", "gp_window")]
        policy = row["policy_window"]["median_us"] / 1e3
        lines.append(
            f"  N = {row['n_via_points']}: {parts[0]:.3f} / {parts[1]:.3f}, "
            f"{parts[2]:.3f}, {policy:.3f}"
        )
    lines.append("obstacles: per episode / EDF per window / PyBullet per window (ms)")
    for row in document["obstacles"]:
        parts = [
            row[key]["median_us"] / 1e3 for key in ("episode", "edf_window", "pybullet_window")
        ]
        lines.append(
            f"  {row['n_obstacles']} boxes: {parts[0]:.3f} / {parts[1]:.3f} / {parts[2]:.3f}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", choices=tuple(SIZES), default="full")
    parser.add_argument("--out", type=Path, help="also write the results as JSON here")
    args = parser.parse_args(argv)
    document = run_study(args.size)
    print(describe(document))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(document, indent=1) + "\n")
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
