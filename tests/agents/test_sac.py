"""RegularisedSAC: the regulariser's gradients reach the actor; schedules are followed."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from distgprl.agents.methods import get_method
from distgprl.agents.regularisers import ActorRegulariser, RegulariserWeights
from distgprl.agents.sac import exponential_anneal
from distgprl.config import EnvConfig
from distgprl.envs.adaptation import build_action_layout
from distgprl.skill.gp import GPSkill, KernelParams


def small_skill(seed=0) -> GPSkill:
    rng = np.random.default_rng(seed)
    tau = np.linspace(0, 1, 15)
    base = np.stack(
        [
            0.4 + 0.2 * tau,
            -0.1 + 0.1 * np.sin(3 * tau),
            0.2 + 0.05 * tau,
            np.full(15, 3.1),
            np.zeros(15),
            0.1 * tau,
        ],
        axis=1,
    )
    return GPSkill(
        KernelParams(0.12, 1.0, 1e-6),
        tau,
        base + 0.001 * rng.normal(size=base.shape),
        base.mean(axis=0),
        4.0,
    )


class QuadraticPrior(torch.nn.Module):
    """Stand-in HAP prior with the same interface: mean squared distance to a point."""

    def __init__(self):
        super().__init__()
        self.register_buffer("target", torch.tensor([0.5, 0.0, 0.2]))

    def loss(self, x):
        return ((x - self.target) ** 2).sum(-1).mean()


def regulariser(method="dist-gprl", lambda_sim=0.5, lambda_hap=0.2):
    skill = small_skill()
    layout = build_action_layout(skill, EnvConfig(), get_method(method))
    weights = RegulariserWeights(lambda_sim=lambda_sim, lambda_hap=lambda_hap)
    prior = QuadraticPrior() if lambda_hap > 0 else None
    return skill, layout, ActorRegulariser(skill, layout, weights, hap_prior=prior)


def aux_batch(skill, layout, batch=4, step=1):
    gamma = np.tile(skill.via_points.ravel(), (batch, 1))
    one_hot = np.zeros((batch, layout.n_steps))
    one_hot[:, step] = 1
    return torch.as_tensor(np.concatenate([gamma, one_hot], 1), dtype=torch.float32)


def test_adapted_via_points_match_the_environment_update():
    skill, layout, reg = regulariser()
    rng = np.random.default_rng(0)
    action = rng.uniform(-1, 1, size=(1, layout.points_per_step * 6))
    adapted = reg.adapted_via_points(
        aux_batch(skill, layout, 1, step=1), torch.as_tensor(action, dtype=torch.float32)
    )
    expected = skill.via_points.copy()
    expected[layout.indices[1]] += layout.delta(1, action[0])
    np.testing.assert_allclose(adapted[0].numpy(), expected, atol=1e-5)


def test_similarity_loss_is_zero_for_the_demonstration_and_grows_with_deviation():
    skill, layout, reg = regulariser()
    centered = torch.as_tensor(skill.via_points - skill.prior_mean, dtype=torch.float32)[None]
    assert reg.similarity_loss(centered).item() == pytest.approx(0.0, abs=1e-5)
    bumped = centered.clone()
    bumped[0, 6, 0] += 0.05
    assert reg.similarity_loss(bumped).item() > 1e-3


@pytest.mark.parametrize(("lambda_sim", "lambda_hap"), [(0.5, 0.0), (0.0, 0.2), (0.5, 0.2)])
def test_regulariser_gradient_reaches_actions_only_when_weighted(lambda_sim, lambda_hap):
    skill, layout, reg = regulariser(lambda_sim=lambda_sim, lambda_hap=lambda_hap)
    actions = torch.zeros(4, layout.points_per_step * 6, requires_grad=True)
    with torch.no_grad():
        actions += 0.3
    total, terms = reg(aux_batch(skill, layout), actions)
    total.backward()
    assert actions.grad.abs().sum() > 0
    assert ("l_sim" in terms) == (lambda_sim > 0)
    assert ("l_hap" in terms) == (lambda_hap > 0)


def test_zero_weights_give_zero_loss_and_no_gradient():
    skill, layout, reg = regulariser(lambda_sim=0.0, lambda_hap=0.0)
    actions = torch.full((4, layout.points_per_step * 6), 0.3, requires_grad=True)
    total, terms = reg(aux_batch(skill, layout), actions)
    assert total.item() == 0.0 and terms == {}
    assert not total.requires_grad


def test_gprl_frozen_via_point_receives_no_update():
    skill = small_skill()
    layout = build_action_layout(skill, EnvConfig(), get_method("gprl"), frozen=(6,))
    delta = layout.delta(0, np.ones(layout.points_per_step * 6))
    assert np.all(delta[layout.indices[0] == 6] == 0)
    assert np.all(delta[layout.indices[0] != 6] != 0)


def test_exponential_anneal_schedule():
    schedule = exponential_anneal(0.2, 0.002)
    assert schedule(0.0) == pytest.approx(0.2)
    assert schedule(1.0) == pytest.approx(0.002)
    assert schedule(0.5) == pytest.approx(0.02)
    values = [schedule(p) for p in np.linspace(0, 1, 11)]
    assert all(a > b for a, b in zip(values, values[1:], strict=False))
    assert schedule(2.0) == pytest.approx(0.002)


def test_critic_frozen_in_the_actor_loss_leaves_the_update_unchanged():
    """The actor loss backpropagates through the critic with its parameters frozen (a
    speed-up); the update must equal SB3's, where they are not, and the critic must be
    trainable again afterwards."""
    from distgprl.experiments.runner import make_agent, make_env, resolve_run

    def trained(freeze: bool) -> torch.Tensor:
        torch.manual_seed(0)
        run = resolve_run("dcp", "dist-gprl", 0, "ci")
        model = make_agent(make_env(run), run)
        model.learning_starts = 12
        if not freeze:  # SB3's original: the critic keeps requires_grad throughout
            model.critic.requires_grad_ = lambda *args, **kwargs: model.critic
        model.learn(18)
        model.train(gradient_steps=3, batch_size=8)
        assert all(p.requires_grad for p in model.critic.parameters())
        return torch.nn.utils.parameters_to_vector(model.policy.parameters()).detach()

    frozen, original = trained(True), trained(False)
    assert torch.equal(frozen, original)
    assert frozen.abs().sum() > 0
