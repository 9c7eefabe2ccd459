"""The naive alternatives the adaptation compute is compared with, in the same run:
PyBullet ``getClosestPoints`` for the EDF, re-solving the GP, SB3 ``predict``."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from distgprl.experiments.bench.pipeline import AdaptationPipeline

__all__ = ["BulletDistance", "naive_pipeline"]


def _shape_bodies(client, shapes) -> list[int]:
    """One static PyBullet body per EDF primitive, built as the task simulations build them."""
    from distgprl.sim.bullet import create_shape_body

    return [create_shape_body(client, shape, (0.5, 0.5, 0.5, 1.0)) for shape in shapes]


class BulletDistance:
    """The naive EDF: PyBullet closest points of a point-sized probe, one query per body.

    The probe (a sphere of ``PROBE_RADIUS``) is moved to each point and
    ``getClosestPoints`` is called against every obstacle body; the minimum plus the probe
    radius is the point's distance. Used for the same points and shapes as the EDF.
    """

    PROBE_RADIUS = 1e-4

    def __init__(self, shapes) -> None:
        import pybullet

        from distgprl.sim.bullet import connect_direct

        self.client = connect_direct()
        shape = self.client.createCollisionShape(pybullet.GEOM_SPHERE, radius=self.PROBE_RADIUS)
        self.probe = self.client.createMultiBody(0, shape)
        self.bodies = _shape_bodies(self.client, shapes)
        self._reset = self.client.resetBasePositionAndOrientation
        self._closest = self.client.getClosestPoints

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Distance (n,) of each point (n, 3) to the nearest body, m (capped at 10 m)."""
        out = np.empty(len(points))
        probe, bodies, reset, closest = self.probe, self.bodies, self._reset, self._closest
        for i, point in enumerate(points.tolist()):
            reset(probe, point, (0.0, 0.0, 0.0, 1.0))
            best = 10.0
            for body in bodies:
                for contact in closest(probe, body, 10.0):
                    best = min(best, contact[8])
            out[i] = best + self.PROBE_RADIUS
        return out

    def close(self) -> None:
        self.client.disconnect()


def naive_pipeline(pipeline: AdaptationPipeline, bullet: BulletDistance, model):
    """Naive counterparts of the pipeline's pieces: PyBullet distances, GP re-solve, SB3
    ``predict``.

    Returns:
        ``(edf, gp, policy)``: ``edf(step)`` the distances (n,), m, of the window via-points
        and tool points from ``bullet``; ``gp(step, action)`` applies the action (the env's
        `apply_action`) and re-solves the GP for the segment's poses (m, 6); ``policy()``
        SB3's deterministic action (A,) for the env's current observation.
    """
    from distgprl.skill.gp import GPSkill

    env = pipeline.env
    skill = env.skill
    obs = env.observation()

    def edf(step: int) -> np.ndarray:
        points = np.concatenate(
            (env.gamma[pipeline.layout.indices[step], :3], pipeline.tool_points)
        )
        return bullet.distance(points)

    def gp(step: int, action: np.ndarray) -> np.ndarray:
        env.apply_action(step, action)
        fresh = GPSkill(skill.kernel, skill.via_times, env.gamma, skill.prior_mean, skill.duration)
        return fresh.position(env.gamma, env.segment_tau(step))

    def policy() -> np.ndarray:
        return model.predict(obs, deterministic=True)[0]

    return edf, gp, policy
