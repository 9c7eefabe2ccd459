"""Build what a run needs from its `RunSpec`: the environment, the actor regulariser, the
agent, and a saved model checked against an environment (`load_model`, shared by the
evaluation of a run and the hardware trials)."""

from __future__ import annotations

from pathlib import Path

from distgprl.errors import UserInputError
from distgprl.identity import RunSpec


def make_env(run: RunSpec):
    """The adaptation environment for a run (ProMP-RRL uses its residual environment, the
    residual-RL variant `ResidualRLEnv`)."""
    if run.method.action_mode == "residual-control":
        from distgprl.envs.residual_control_env import ResidualRLEnv

        return ResidualRLEnv(run.task, run.method, run.config.env)
    if run.method.action_mode == "residual":
        from distgprl.envs.windowed_residual_env import ResidualEnv

        return ResidualEnv(run.task, run.config.env, method=run.method)
    from distgprl.envs.via_point_env import AdaptationEnv

    return AdaptationEnv(run.task, run.method, run.config.env)


def build_regulariser(env, run: RunSpec):
    """lambda_sim L_sim + lambda_hap L_hap for methods that use them, else None."""
    method, sac = run.method, run.config.sac
    if not (method.similarity_loss or method.hap_prior):
        return None
    from distgprl.agents.regularisers import ActorRegulariser, RegulariserWeights

    hap_prior = None
    if method.hap_prior:
        from distgprl.envs.tasks import load_task_hap_prior

        hap_prior = load_task_hap_prior(
            run.task, k=sac.hap_k, temperature=sac.hap_temperature, hinge=sac.hap_hinge
        )
    weights = RegulariserWeights(
        lambda_sim=sac.lambda_sim if method.similarity_loss else 0.0,
        lambda_hap=sac.lambda_hap if method.hap_prior else 0.0,
        lambda_velocity=sac.lambda_velocity,
        lambda_acceleration=sac.lambda_acceleration,
    )
    return ActorRegulariser(
        env.skill,
        env.layout,
        weights,
        hap_prior=hap_prior,
        n_similarity_samples=sac.n_similarity_samples,
        n_hap_queries=sac.hap_n_query,
        moving_filter=env.moving_obstacle_filter() if method.hap_prior else None,
    )


def make_agent(env, run: RunSpec, regularised: bool = True):
    """A `RegularisedSAC` configured from the run's shared SAC configuration; with
    ``regularised=False`` without its actor regulariser (an agent that only acts, e.g. to hold
    a shipped actor: no HAP subspace is built)."""
    from distgprl.agents.sac import RegularisedSAC, StateOnlyExtractor, exponential_anneal

    sac = run.config.sac
    anneal = run.method.entropy == "anneal"
    return RegularisedSAC(
        "MultiInputPolicy",
        env,
        learning_rate=sac.learning_rate,
        # SB3 preallocates the whole buffer (and pickles all of it in checkpoints); a run
        # never stores more than total_steps transitions, so the smaller size is equivalent.
        buffer_size=min(sac.buffer_size, run.config.run.total_steps),
        batch_size=sac.batch_size,
        gamma=sac.gamma,
        tau=sac.tau,
        learning_starts=sac.learning_starts,
        train_freq=sac.train_freq,
        gradient_steps=sac.gradient_steps,
        ent_coef=sac.anneal_start if anneal else f"auto_{sac.ent_coef_init}",
        policy_kwargs={
            "features_extractor_class": StateOnlyExtractor,
            "net_arch": list(sac.net_arch),
            # Fused (single-kernel) Adam: the same update, 2x faster on one CPU thread.
            "optimizer_kwargs": {"fused": True},
        },
        seed=run.seed,
        device="cpu",
        verbose=0,
        regulariser=build_regulariser(env, run) if regularised else None,
        entropy_schedule=exponential_anneal(sac.anneal_start, sac.anneal_end) if anneal else None,
        total_training_steps=run.config.run.total_steps,
    )


def load_model(path: Path, env, task: str, method: str):
    """The `RegularisedSAC` saved at ``path`` (a ``model.zip``), refused with a
    `UserInputError` if it cannot be read or if its observation and action spaces are not
    ``env``'s (the ``task``/``method`` environment the model is to run in)."""
    from distgprl.agents.sac import RegularisedSAC

    try:
        model = RegularisedSAC.load_saved(path)
    except Exception as exc:  # an unreadable zip is the user's input problem
        raise UserInputError(f"{path}: cannot load model ({type(exc).__name__}: {exc})") from None
    if model.observation_space != env.observation_space or model.action_space != env.action_space:
        raise UserInputError(f"{path}: model spaces do not match the {task}/{method} environment")
    return model
