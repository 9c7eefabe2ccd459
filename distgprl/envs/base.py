"""What the task environments share (`AdaptationEnv`, `ResidualRLEnv`): the builder (the
task's simulation and skill, the method), the generator of training TCs, the episode's start
and the gymnasium plumbing."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from distgprl.config_types import EnvConfig
from distgprl.methods import MethodSpec, get_method
from distgprl.skill.gp import GPSkill

__all__ = ["RELATIVE_POSITION_CLIP", "TaskEnv"]

RELATIVE_POSITION_CLIP = 0.8
"""Observed relative positions (e_o, e_g, ...) are clipped to +-this per axis (m) before
scaling (a knocked-off object must not blow the inputs up)."""


class TaskEnv(gym.Env):
    """A task's episode environment: `build` gives it the task's simulation (``sim``,
    ``spec_task``), its demonstrated skill (``skill``), the method and the env config."""

    metadata = {"render_modes": ["rgb_array"]}

    def build(
        self,
        task: str,
        method: str | MethodSpec,
        config: EnvConfig | None,
        render_mode: str | None,
        action_modes: tuple[str, ...],
        refusal: str,
        skill: GPSkill | None = None,
    ) -> None:
        """Build the shared parts; a method whose action mode is not in ``action_modes`` is a
        ``ValueError`` (``refusal``, formatted with ``name``)."""
        from distgprl.envs.tasks import load_task_skill, make_task_sim

        self.config = config or EnvConfig()
        self.method = method if isinstance(method, MethodSpec) else get_method(method)
        if self.method.action_mode not in action_modes:
            raise ValueError(refusal.format(name=self.method.name))
        self.task_name = task
        self.render_mode = render_mode
        self.spec_task, self.sim = make_task_sim(task)
        self.skill = skill or load_task_skill(task, self.config.n_via_points)
        self._rng = np.random.default_rng()
        self.step_index = 0
        self._episode_over = True  # until reset()

    def episode_tc(self, seed: int | None, options: dict | None):
        """`reset`'s TC: ``options["tc"]``, else one drawn from the task's training
        distribution with the env's generator (reseeded by ``seed``)."""
        super().reset(seed=seed)
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        tc = (options or {}).get("tc")
        return self.spec_task.sample_tc(self._rng) if tc is None else tc

    def relative(self, vector: np.ndarray) -> np.ndarray:
        """A relative position (3,), m, clipped and in units of relative_position_scale."""
        clipped = np.clip(vector, -RELATIVE_POSITION_CLIP, RELATIVE_POSITION_CLIP)
        return clipped / self.config.relative_position_scale

    @property
    def tc_generator_state(self) -> Mapping[str, Any]:
        """The state of the generator that draws the training TCs at ``reset()`` (NumPy
        ``bit_generator.state``; a training checkpoint saves and restores it)."""
        return self._rng.bit_generator.state

    @tc_generator_state.setter
    def tc_generator_state(self, state: dict) -> None:
        self._rng.bit_generator.state = state

    @property
    def at_episode_start(self) -> bool:
        """True between ``reset()`` and the episode's first step (where a training run can be
        checkpointed and resumed exactly)."""
        return self.step_index == 0 and not self._episode_over

    def render(self):
        if self.render_mode == "rgb_array":
            return self.sim.render_rgb(480, 360)
        return None

    def close(self) -> None:
        self.sim.close()
