"""The public Python API: the CLI's commands as functions, for notebooks and scripts.

Each function is a thin wrapper over the library function the CLI calls
(`distgprl.experiments.training`, `distgprl.experiments.evaluation`,
`distgprl.experiments.skills`), with the CLI's defaults::

    import distgprl

    folder = distgprl.train("dcp", "dist-gprl", seed=0, preset="ci", root="runs")
    policy = distgprl.load_policy("dcp", "dist-gprl", 0, preset="ci", root="runs")
    env = distgprl.make_env("dcp", "dist-gprl", preset="ci")
    obs, _ = env.reset(seed=1)
    action = policy.predict(obs)        # (action_dim,) float32, in [-1, 1]

Presets are the shipped ones (``paper``, ``ci``, the study presets) or a YAML file of the
user's own, given as ``config=PATH`` (named after its stem, as the CLI's ``--preset-file``);
a preset name may carry overrides (`distgprl.config.preset_with_overrides`). Nothing here
imports torch or pybullet until a function is called, so ``import distgprl`` stays cheap.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from distgprl.errors import UserInputError

if TYPE_CHECKING:
    import gymnasium

    from distgprl.experiments.skills import FitOutput
    from distgprl.identity import RunSpec

__all__ = ["Policy", "evaluate", "fit_skill", "load_policy", "make_env", "train"]


def _preset(preset: str, config: str | Path | None) -> str:
    """``preset``, or the name ``config`` (a YAML file) is registered under."""
    if config is None:
        return preset
    from distgprl.config import register_preset

    return register_preset(config)


def make_env(
    task: str, method: str = "dist-gprl", preset: str = "paper", config: str | Path | None = None
) -> gymnasium.Env:
    """The adaptation environment a run of ``method`` on ``task`` trains and is evaluated in
    (`distgprl.experiments.factories.make_env`; ProMP-RRL's residual environment for
    ``promp-rrl``). Observations are dicts; ``obs["state"]`` is what the policies read.

    Close it with ``env.close()`` (it holds a PyBullet client).
    """
    from distgprl.experiments.factories import make_env as _make_env
    from distgprl.identity import resolve_run

    return _make_env(resolve_run(task, method, 0, _preset(preset, config)))


@dataclass(frozen=True)
class Policy:
    """A trained run's policy (or the unadapted reference's zero action for ``demo``).

    Attributes:
        run: the run's resolved specification (task, method, seed, configuration).
        folder: the run folder the policy was loaded from.
        model: the `RegularisedSAC` (SB3 SAC) holding the policy; None for ``demo``.
        selected: for ``policy="best"``, the selected learning-curve step and its figures.
        action_shape: (action_dim,) of the environment's raw action.
    """

    run: RunSpec
    folder: Path
    model: Any
    selected: dict[str, Any]
    action_shape: tuple[int, ...]
    _actor: Callable[[dict[str, np.ndarray]], np.ndarray] | None = field(default=None, repr=False)

    def predict(self, obs: dict[str, np.ndarray], deterministic: bool = True) -> np.ndarray:
        """The action for one observation of `make_env`'s environment.

        Args:
            obs: the environment's observation (a dict with ``"state"``, shape (obs_dim,)).
            deterministic: the actor's mean action (what every evaluation uses, computed as
                the evaluation computes it, `deterministic_policy`), or else a sample of
                SAC's squashed Gaussian policy.

        Returns:
            The raw action, shape (action_dim,), float32, in [-1, 1] (the environment scales
            it into via-point changes); zeros for ``demo``.
        """
        if self.model is None:
            return np.zeros(self.action_shape, dtype=np.float32)
        if deterministic:
            assert self._actor is not None, "a Policy with a model has its actor (load_policy)"
            return np.asarray(self._actor(obs), dtype=np.float32)
        action, _ = self.model.predict(obs, deterministic=False)
        return np.asarray(action, dtype=np.float32)

    def __call__(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """`predict` with ``deterministic=True`` (a ``policy(obs)`` callable, as
        `distgprl.experiments.rollout.run_episode` takes)."""
        return self.predict(obs)


def load_policy(
    task: str,
    method: str,
    seed: int,
    preset: str = "paper",
    root: str | Path = "results",
    policy: str = "final",
    config: str | Path | None = None,
) -> Policy:
    """Load the policy of the trained run ``<root>/<preset>/<task>/<method>/seed<k>``.

    Args:
        policy: ``final`` (``model.zip``, the run's last step: Table I of the final policy)
            or ``best`` (Algorithm 1's best trained learning-curve policy, what Table I
            reports; `distgprl.experiments.policies.best_curve_row`).

    Raises:
        UserInputError: unknown names, no trained model there, or a model of a configuration
            other than the one the code resolves now (as ``distgprl evaluate``).
    """
    from distgprl.experiments.factories import make_env as _make_env
    from distgprl.experiments.policies import load_trained_policy
    from distgprl.experiments.rollout import deterministic_policy
    from distgprl.identity import resolve_run
    from distgprl.schema import run_dir

    if policy not in ("final", "best"):
        raise UserInputError(f"policy must be 'final' or 'best', got {policy!r}")
    preset = _preset(preset, config)
    run = resolve_run(task, method, seed, preset)
    folder = run_dir(root, preset, task, method, seed)
    if policy == "best" and not run.method.trainable:
        raise UserInputError(f"{method} is not trained: it has no learning curve to select from")
    env = _make_env(run)
    try:
        shape = tuple(env.action_space.shape)
        if not run.method.trainable:
            return Policy(run, folder, None, {}, shape)
        trained = load_trained_policy(run, folder, env, policy)
    finally:
        env.close()
    model = trained.model
    return Policy(trained.run, folder, model, trained.selected, shape, deterministic_policy(model))


def train(
    task: str,
    method: str,
    seed: int = 0,
    preset: str = "paper",
    steps: int | None = None,
    resume: bool = False,
    root: str | Path = "results",
    evaluate: bool = True,
    progress: bool = True,
    config: str | Path | None = None,
) -> Path:
    """Train one run (``distgprl train``; `distgprl.experiments.training.train_run`) and, by
    default, evaluate it; return the run folder ``<root>/<preset>/<task>/<method>/seed<k>``.

    ``steps`` overrides the preset's total RL steps (a multiple of the episode length, 3).
    """
    from distgprl.experiments.training import train_run

    return train_run(
        task,
        method,
        seed,
        _preset(preset, config),
        steps,
        resume,
        root,
        show_progress=progress,
        evaluate_after=evaluate,
    )


def evaluate(
    task: str,
    method: str,
    seed: int = 0,
    preset: str = "paper",
    episodes: int | None = None,
    root: str | Path = "results",
    policy: str = "final",
    progress: bool = True,
    config: str | Path | None = None,
) -> dict[str, Any]:
    """Evaluate a trained run or the ``demo`` reference (``distgprl evaluate``;
    `distgprl.experiments.evaluation.evaluate_run`): writes its ``evaluation*.csv`` and
    ``summary*.json`` and returns the summary (success and collision rates in [0, 1],
    ``min_clearance_p5`` in m, means)."""
    from distgprl.experiments.evaluation import evaluate_run

    return evaluate_run(
        task,
        method,
        seed,
        _preset(preset, config),
        episodes,
        root,
        show_progress=progress,
        policy=policy,
    )


def fit_skill(
    task: str | None = None,
    demo: str | Path | None = None,
    n_via_points: int = 15,
    out_dir: str | Path = "results/skills",
) -> FitOutput:
    """Fit the GP via-point skill (``distgprl fit``;
    `distgprl.experiments.skills.fit_demonstration`) to a task's shipped demonstration or a
    demonstration CSV (columns ``t,x,y,z,rx,ry,rz``: s, m, rad); writes ``<name>.json`` and a
    figure into ``out_dir`` and returns them with the skill, its reconstruction RMSE and the
    covariance transform's summary."""
    from distgprl.data import demo_path
    from distgprl.experiments.skills import fit_demonstration
    from distgprl.skill.gp import FitConfig

    if (task is None) == (demo is None):
        raise UserInputError("give exactly one of task or demo")
    source = demo_path(task) if task is not None else Path(cast("str | Path", demo))  # one of them
    return fit_demonstration(
        source, out_dir, name=task, config=FitConfig(n_via_points=n_via_points)
    )
