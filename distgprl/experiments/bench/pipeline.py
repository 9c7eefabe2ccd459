"""The adaptation compute of one episode (EDF, GP conditioning, policy), isolated from the
simulation: what section 1 and the scaling curves time."""

from __future__ import annotations

import numpy as np

from distgprl.agents.numpy_actor import NumpyActor
from distgprl.envs.episode import plan_segment

__all__ = ["AdaptationPipeline"]


class AdaptationPipeline:
    """The adaptation compute of one episode, isolated from the simulation.

    Per window k (as `AdaptationEnv.step` does, plus policy inference): the actor maps the
    observation to a raw action (policy: the SAC actor's weights run by `NumpyActor`); the EDF
    is refreshed from the obstacle shapes and queried at the window via-points and the tool
    points (EDF); the window's via-points are updated with Delta Gamma = S_W a and the segment
    to execute is re-evaluated from the GP's precomputed map (GP conditioning). The obstacle
    shapes and tool points are read from the simulator once (state reads are not compute; the
    env's own timer includes them).

    Args:
        env: an `AdaptationEnv` after `reset` (its layout, skill, segment maps and field).
        actor: the SB3 SAC actor (``actor(obs, deterministic=True)``).
        field: the distance field to query (default the env's).
        shapes: obstacle shapes for the field's update (default the env's current ones).
    """

    def __init__(self, env, actor, field=None, shapes=None) -> None:
        import torch

        self.env = env
        self.actor = actor
        self.numpy_actor = NumpyActor(actor)
        self.field = field if field is not None else env.field
        self.shapes = tuple(shapes) if shapes is not None else tuple(env.sim.obstacle_shapes())
        self.tool_points = np.asarray(env.sim.tool_points())
        self.gamma_initial = env.gamma.copy()
        self.state = env.observation()["state"]
        self.layout = env.layout
        self._torch = torch
        rng = np.random.default_rng(0)
        self.actions = rng.uniform(-1, 1, (self.layout.n_steps, self.layout.points_per_step * 6))

    def edf(self, step: int) -> tuple[np.ndarray, np.ndarray]:
        """EDF update and query at the window via-points and tool points."""
        self.field.update(self.shapes)
        indices = self.layout.indices[step]
        points = np.concatenate((self.env.gamma[indices, :3], self.tool_points))
        return self.field.distance(points)

    def gp_conditioning(self, step: int, action: np.ndarray) -> np.ndarray:
        """Delta Gamma = S_W a on the window, then the segment's poses (m, 6) (the episode
        loop's `plan_segment`)."""
        return plan_segment(self.env, step, action)[1]

    def policy(self) -> np.ndarray:
        """Deterministic action for the current observation, (A,) (`NumpyActor`)."""
        return self.numpy_actor(self.state)

    def policy_torch(self) -> np.ndarray:
        """The same action from the torch actor (``inference_mode``), (A,)."""
        torch = self._torch
        with torch.inference_mode():
            state = torch.as_tensor(self.state).unsqueeze(0)
            return self.actor({"state": state}, deterministic=True)[0].numpy()

    def window(self, step: int) -> np.ndarray:
        """Policy + EDF + GP conditioning of one window."""
        action = self.policy()
        self.edf(step)
        return self.gp_conditioning(step, action)

    def restart(self) -> None:
        self.env.gamma[:] = self.gamma_initial

    def episode(self) -> None:
        """All windows of one episode (from the episode's initial via-points)."""
        self.restart()
        for step in range(self.layout.n_steps):
            self.window(step)
