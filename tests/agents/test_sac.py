"""RegularisedSAC: the regulariser's gradients reach the actor; schedules are followed."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from distgprl.adaptation.layout import OBSERVATION_SCALE_FLOOR, build_action_layout
from distgprl.agents.regularisers import ActorRegulariser, RegulariserWeights
from distgprl.agents.sac import exponential_anneal, training_logger
from distgprl.config_types import EnvConfig
from distgprl.methods import get_method
from distgprl.safety.hap_filter import MovingObstacleFilter
from distgprl.safety.hap_loss import HapPrior
from distgprl.safety.shapes import Box
from distgprl.skill.gp import GPSkill
from distgprl.skill.kernels import KernelParams

# v5's operator and fixed scales: these tests check the plumbing, not the v6 reading
# (tests/adaptation/test_layout.py checks the Table I operator and the reach rule).
V5_OPERATOR = EnvConfig(covariance_scale="signal", action_scale_rule="fixed")


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
        axis_scale=np.full(6, 0.1),
    )


class QuadraticPrior(torch.nn.Module):
    """Stand-in HAP prior with the same interface: mean squared distance to a point."""

    def __init__(self):
        super().__init__()
        self.register_buffer("target", torch.tensor([0.5, 0.0, 0.2]))

    def loss(self, x):
        return ((x - self.target) ** 2).sum(-1).mean()


def regulariser(method="dist-gprl", lambda_sim=0.5, lambda_hap=0.2, frozen=()):
    skill = small_skill()
    layout = build_action_layout(skill, V5_OPERATOR, get_method(method), frozen=frozen)
    weights = RegulariserWeights(lambda_sim=lambda_sim, lambda_hap=lambda_hap)
    prior = QuadraticPrior() if lambda_hap > 0 else None
    return skill, layout, ActorRegulariser(skill, layout, weights, hap_prior=prior)


def aux_batch(skill, layout, batch=4, step=1):
    gamma = np.tile(skill.via_points.ravel(), (batch, 1))
    one_hot = np.zeros((batch, layout.n_steps))
    one_hot[:, step] = 1
    return torch.as_tensor(np.concatenate([gamma, one_hot], 1), dtype=torch.float32)


@pytest.mark.parametrize("step", [0, 1, 2])
@pytest.mark.parametrize(
    ("method", "frozen"),
    [("dist-gprl", ()), ("dist-gprl-global", ()), ("dist-gprl-nocov", ()), ("gprl", (6,))],
)
def test_adapted_via_points_match_the_environment_update(method, frozen, step):
    """The regulariser's Gamma + S_W (scale * a) equals the environment's update (layout.delta)
    and an independent computation with the skill's own S_W (identity without the covariance
    transform; frozen via-points unchanged), at every step, for windowed and global layouts."""
    skill, layout, reg = regulariser(method, frozen=frozen)
    spec = get_method(method)
    rng = np.random.default_rng(step)
    action = rng.uniform(-1, 1, size=(1, layout.points_per_step * 6))
    gamma = skill.via_points + 0.01 * rng.normal(size=skill.via_points.shape)
    aux = aux_batch(skill, layout, 1, step=step)
    aux[:, : gamma.size] = torch.as_tensor(gamma.ravel(), dtype=torch.float32)
    adapted = reg.adapted_via_points(aux, torch.as_tensor(action, dtype=torch.float32))

    indices = layout.indices[step]
    scaled = action[0].reshape(-1, 6) * layout.scale
    if spec.covariance_transform:  # v5: per axis, K_a = sigma_f^2 s_a^2 R
        variance = (
            skill.kernel.signal_variance
            * np.maximum(skill.axis_scale, OBSERVATION_SCALE_FLOOR) ** 2
        )
        operators = [
            skill.window_operator(indices, EnvConfig().correlation_lambda / v) for v in variance
        ]
        assert not np.allclose(operators[0], np.eye(len(indices)), atol=1e-3)
    else:
        operators = [np.eye(len(indices))] * 6
    delta = np.stack([operators[a] @ scaled[:, a] for a in range(6)], axis=1)
    delta[np.isin(indices, frozen)] = 0.0
    expected = gamma.copy()
    expected[indices] += delta
    np.testing.assert_allclose(adapted[0].numpy(), expected, atol=1e-5)

    environment = gamma.copy()
    environment[indices] += layout.delta(step, action[0])
    np.testing.assert_allclose(adapted[0].numpy(), environment, atol=1e-5)
    untouched = np.setdiff1d(np.arange(skill.n_via_points), np.setdiff1d(indices, frozen))
    np.testing.assert_allclose(adapted[0].numpy()[untouched], gamma[untouched], atol=1e-6)
    if spec.covariance_transform:  # the check can tell S_W from the identity
        assert np.abs(scaled - delta).max() > 1e-3


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


def separate_term_gradients(skill, reg, aux, actions, n_hap_queries=20):
    """(L_sim, grad L_sim, L_hap, grad L_hap) w.r.t. the actions, each term computed on its
    own (L_hap from the skill's position map and the stand-in prior, not from forward)."""
    leaf = actions.detach().clone().requires_grad_(True)
    centered = reg.adapted_via_points(aux, leaf) - reg.prior_mean
    l_sim = reg.similarity_loss(centered).mean()
    (g_sim,) = torch.autograd.grad(l_sim, leaf)
    leaf = actions.detach().clone().requires_grad_(True)
    centered = reg.adapted_via_points(aux, leaf) - reg.prior_mean
    hap_map = torch.as_tensor(
        skill.position_map(np.linspace(0.0, 1.0, n_hap_queries)), dtype=torch.float32
    )
    prior_mean = torch.as_tensor(skill.prior_mean, dtype=torch.float32)
    positions = (torch.matmul(hap_map, centered) + prior_mean)[..., :3]
    l_hap = QuadraticPrior().loss(positions)
    (g_hap,) = torch.autograd.grad(l_hap, leaf)
    return l_sim.item(), g_sim, l_hap.item(), g_hap


def mixed_step_batch(skill, layout, seed=0):
    """Four observations' aux (steps 0, 1, 2, 1) and random actions in [-1, 1]."""
    rng = np.random.default_rng(seed)
    aux = torch.cat([aux_batch(skill, layout, 1, step=s) for s in (0, 1, 2, 1)])
    actions = torch.as_tensor(
        rng.uniform(-1, 1, size=(4, layout.points_per_step * 6)), dtype=torch.float32
    )
    return aux, actions


def total_and_gradient(reg, aux, actions):
    leaf = actions.detach().clone().requires_grad_(True)
    total, terms = reg(aux, leaf)
    (gradient,) = torch.autograd.grad(total, leaf)
    return total.item(), terms, gradient


@pytest.mark.parametrize(
    ("lambda_sim", "lambda_hap"), [(0.5, 0.0), (0.0, 0.2), (0.5, 0.2), (1.7, 0.3)]
)
def test_regulariser_gradient_is_the_lambda_weighted_sum_of_the_term_gradients(
    lambda_sim, lambda_hap
):
    """d total / d a = lambda_sim dL_sim/da + lambda_hap dL_hap/da (and the same for the
    values), with each term computed separately, so a dropped or misplaced lambda fails."""
    skill, layout, reg = regulariser(lambda_sim=lambda_sim, lambda_hap=lambda_hap)
    aux, actions = mixed_step_batch(skill, layout)
    l_sim, g_sim, l_hap, g_hap = separate_term_gradients(skill, reg, aux, actions)
    assert g_sim.abs().max() > 1e-4 and g_hap.abs().max() > 1e-4
    assert not torch.allclose(g_sim, g_hap, rtol=0.1)  # the two terms are distinguishable

    total, terms, gradient = total_and_gradient(reg, aux, actions)
    expected = lambda_sim * g_sim + lambda_hap * g_hap
    scale = expected.abs().max().item()
    torch.testing.assert_close(gradient, expected, rtol=1e-4, atol=1e-5 * scale)
    assert total == pytest.approx(lambda_sim * l_sim + lambda_hap * l_hap, rel=1e-5)
    if lambda_sim > 0:
        assert terms["l_sim"] == pytest.approx(l_sim, rel=1e-5)
    if lambda_hap > 0:
        assert terms["l_hap"] == pytest.approx(l_hap, rel=1e-5)


@pytest.mark.parametrize("doubled", ["lambda_sim", "lambda_hap"])
def test_doubling_a_lambda_doubles_its_contribution(doubled):
    """With lambda_x doubled, total and gradient grow by exactly lambda_x L_x and
    lambda_x dL_x/da; the other term's contribution is unchanged."""
    weights = {"lambda_sim": 0.5, "lambda_hap": 0.2}
    skill, layout, base = regulariser(**weights)
    _, _, twice = regulariser(**{**weights, doubled: 2 * weights[doubled]})
    aux, actions = mixed_step_batch(skill, layout, seed=1)
    l_sim, g_sim, l_hap, g_hap = separate_term_gradients(skill, base, aux, actions)
    term, gradient_term = (l_sim, g_sim) if doubled == "lambda_sim" else (l_hap, g_hap)

    total_1, _, gradient_1 = total_and_gradient(base, aux, actions)
    total_2, _, gradient_2 = total_and_gradient(twice, aux, actions)
    added = weights[doubled] * gradient_term
    torch.testing.assert_close(
        gradient_2 - gradient_1, added, rtol=1e-4, atol=1e-5 * gradient_2.abs().max().item()
    )
    assert total_2 - total_1 == pytest.approx(weights[doubled] * term, rel=1e-4)
    assert not torch.allclose(gradient_2, gradient_1, rtol=1e-3)


def test_zero_weights_give_zero_loss_and_no_gradient():
    skill, layout, reg = regulariser(lambda_sim=0.0, lambda_hap=0.0)
    actions = torch.full((4, layout.points_per_step * 6), 0.3, requires_grad=True)
    total, terms = reg(aux_batch(skill, layout), actions)
    assert total.item() == 0.0 and terms == {}
    assert not total.requires_grad


def test_gprl_frozen_via_point_receives_no_update():
    skill = small_skill()
    layout = build_action_layout(skill, V5_OPERATOR, get_method("gprl"), frozen=(6,))
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
    from distgprl.experiments.factories import make_agent, make_env
    from distgprl.identity import resolve_run

    def trained(freeze: bool) -> torch.Tensor:
        torch.manual_seed(0)
        run = resolve_run("dcp", "dist-gprl", 0, "ci")
        model = make_agent(make_env(run), run)
        model.learning_starts = 12
        model.freeze_critic_in_actor_loss = freeze  # False: SB3's original
        model.learn(18)
        model.train(gradient_steps=3, batch_size=8)
        assert all(p.requires_grad for p in model.critic.parameters())
        return torch.nn.utils.parameters_to_vector(model.policy.parameters()).detach()

    frozen, original = trained(True), trained(False)
    assert torch.equal(frozen, original)
    assert frozen.abs().sum() > 0


# -- the real agent ------------------------------------------------------------------------
def real_observations(env, episodes=2):
    """Observations at every step (0, 1, 2) of a few random-action episodes, batched (an
    episode a collision ends early contributes its steps up to the collision)."""
    rng = np.random.default_rng(0)
    observations = []
    for episode in range(episodes):
        obs, _ = env.reset(seed=episode)
        for _ in range(env.layout.n_steps):
            observations.append(obs)
            action = 0.3 * rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
            obs, _, terminated, _, _ = env.step(action)
            if terminated:
                break
    return {
        key: torch.as_tensor(np.stack([o[key] for o in observations]), dtype=torch.float32)
        for key in observations[0]
    }


@pytest.fixture(scope="module")
def dist_gprl_agent():
    from distgprl.experiments.factories import make_agent, make_env
    from distgprl.identity import resolve_run

    torch.manual_seed(0)
    run = resolve_run("dcp", "dist-gprl", 0, "ci")
    env = make_env(run)
    model = make_agent(env, run)
    return env, model, real_observations(env)


@pytest.mark.parametrize("terms_used", ["both", "l_sim", "l_hap"])
def test_real_agent_regulariser_gradient_reaches_every_actor_parameter(dist_gprl_agent, terms_used):
    """Dist-GPRL (ci preset): backpropagating only the regulariser of actions_pi sampled by
    the actor on real observations gives every actor parameter (latent_pi, mu, log_std) a
    non-zero gradient, for L_sim and the task's real L_hap alone and together; the critic
    gets none."""
    env, model, obs = dist_gprl_agent
    n = env.config.n_via_points
    steps = obs["aux"][:, n * 6 : n * 6 + env.layout.n_steps].argmax(dim=1)
    assert set(steps.tolist()) == set(range(env.layout.n_steps))
    reg = model.regulariser
    assert isinstance(reg, ActorRegulariser)
    assert reg.weights.lambda_sim > 0 and reg.weights.lambda_hap > 0
    assert reg.hap_prior is not None and reg.moving_filter is not None
    if terms_used != "both":
        weights = RegulariserWeights(
            lambda_sim=reg.weights.lambda_sim if terms_used == "l_sim" else 0.0,
            lambda_hap=reg.weights.lambda_hap if terms_used == "l_hap" else 0.0,
            lambda_velocity=reg.weights.lambda_velocity,
            lambda_acceleration=reg.weights.lambda_acceleration,
        )
        reg = ActorRegulariser(
            env.skill,
            env.layout,
            weights,
            hap_prior=reg.hap_prior,
            n_similarity_samples=model.regulariser.velocity_map.shape[0],
            n_hap_queries=model.regulariser.hap_map.shape[0],
            moving_filter=model.regulariser.moving_filter,
        )

    model.actor.zero_grad(set_to_none=True)
    model.critic.zero_grad(set_to_none=True)
    actions_pi, _ = model.actor.action_log_prob(obs)
    total, terms = reg(obs["aux"], actions_pi)
    expected_terms = {"l_sim", "l_hap"} if terms_used == "both" else {terms_used}
    assert set(terms) == expected_terms
    assert total.requires_grad and total.item() != 0.0
    total.backward()

    names = [name for name, _ in model.actor.named_parameters()]
    assert any(n.startswith("latent_pi.") for n in names) and "mu.weight" in names
    for name, parameter in model.actor.named_parameters():
        assert parameter.grad is not None, name
        assert parameter.grad.abs().sum() > 0, name
        assert torch.isfinite(parameter.grad).all(), name
    assert all(p.grad is None for p in model.critic.parameters())


@pytest.mark.parametrize(
    ("method", "expected"),
    [
        ("gprl", None),
        ("promp-rrl-windowed", None),
        ("gprl-d", {"l_sim"}),
        ("gprl-h", {"l_sim", "l_hap"}),
    ],
)
def test_real_agent_regulariser_only_has_the_terms_the_method_weights(method, expected):
    """build_regulariser / make_agent: GPRL and ProMP-RRL (no L_sim, no L_hap) get no
    regulariser; GPRL-D (no HAP) gets lambda_hap = 0, no prior and total = lambda_sim L_sim;
    GPRL-H keeps both terms."""
    from distgprl.experiments.factories import build_regulariser, make_agent, make_env
    from distgprl.identity import resolve_run

    torch.manual_seed(0)
    run = resolve_run("dcp", method, 0, "ci")
    env = make_env(run)
    assert (build_regulariser(env, run) is None) == (expected is None)
    model = make_agent(env, run)
    if expected is None:
        assert model.regulariser is None
        return
    reg = model.regulariser
    assert (reg.weights.lambda_hap > 0) == ("l_hap" in expected)
    assert (reg.hap_prior is not None) == ("l_hap" in expected)
    assert reg.weights.lambda_sim > 0
    obs = real_observations(env, episodes=1)
    model.actor.zero_grad(set_to_none=True)
    actions_pi, _ = model.actor.action_log_prob(obs)
    total, terms = reg(obs["aux"], actions_pi)
    assert set(terms) == expected
    if expected == {"l_sim"}:
        assert total.item() == pytest.approx(reg.weights.lambda_sim * terms["l_sim"], rel=1e-5)
    total.backward()
    assert model.actor.mu.weight.grad.abs().sum() > 0


def test_learning_leaves_no_logger_folder_in_the_temp_dir(tmp_path, monkeypatch):
    """A silent model records its training terms in memory: SB3's default logger would make
    an empty SB3-<time> folder in the temporary directory at every learn() call."""
    import tempfile

    from distgprl.experiments.factories import make_agent, make_env
    from distgprl.identity import resolve_run

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    run = resolve_run("dcp", "dist-gprl", 0, "ci")
    model = make_agent(make_env(run), run)
    model.learning_starts = 6
    model.learn(9)
    model.learn(3, reset_num_timesteps=False)  # as a resumed run does
    assert not list(tmp_path.glob("SB3-*"))
    assert model.logger.name_to_value or model.last_regulariser_terms  # terms still recorded


def test_l_hap_filters_c_safe_with_the_moving_obstacles_anchors_from_aux():
    """With a moving-obstacle filter, L_hap reads the obstacles' anchors (at the via-point
    times) from the end of aux: an obstacle parked on the trajectory's nearest C_safe points
    raises L_hap, one far away leaves it as without the filter; the gradient still reaches the
    actions; an aux without anchors is a clear error."""
    skill = small_skill()
    layout = build_action_layout(skill, V5_OPERATOR, get_method("dist-gprl"))
    axes = [np.arange(0.3, 0.71, 0.1), np.arange(-0.3, 0.31, 0.1), np.arange(0.1, 0.41, 0.1)]
    c_safe = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    prior = HapPrior(c_safe)
    obstacle = (Box("cube", np.zeros(3), np.eye(3), np.full(3, 0.05), True),)
    moving = MovingObstacleFilter(obstacle, np.zeros(3), np.full(3, 0.02), margin=0.03)
    weights = RegulariserWeights(lambda_sim=0.0, lambda_hap=1.0)
    filtered = ActorRegulariser(skill, layout, weights, hap_prior=prior, moving_filter=moving)
    plain = ActorRegulariser(skill, layout, weights, hap_prior=prior)
    base = aux_batch(skill, layout, batch=2)
    n = skill.n_via_points
    on_path = np.tile(skill.via_points[:, :3], (1, 1)).ravel()  # the obstacle follows the path
    far = np.tile([5.0, 5.0, 5.0], n)
    aux = torch.cat([base, torch.as_tensor(np.stack([on_path, far]), dtype=torch.float32)], 1)
    actions = torch.zeros(2, layout.points_per_step * 6, requires_grad=True)
    per_sample = [filtered(aux[i : i + 1], actions[i : i + 1])[1]["l_hap"] for i in range(2)]
    reference = plain(base[:1], actions[:1])[1]["l_hap"]
    assert per_sample[0] > reference + 0.01
    assert per_sample[1] == pytest.approx(reference, abs=1e-6)
    total, _ = filtered(aux, actions + 0.1)
    total.backward()
    assert actions.grad is not None and actions.grad.abs().sum() > 0
    with pytest.raises(ValueError, match="moving-obstacle filter needs"):
        filtered(base, actions)


def test_term_gradients_split_the_fused_gradient_into_its_terms(dist_gprl_agent):
    """`ActorRegulariser.term_gradients`: the weighted terms' gradients sum to the autograd
    gradient of the whole regulariser, and L_sim's equals an autograd gradient through the
    unfused similarity loss (so the split is not just any two summands)."""
    env, model, observations = dist_gprl_agent
    reg = model.regulariser
    aux = observations["aux"].double()
    actions = torch.as_tensor(
        np.random.default_rng(5).uniform(-1, 1, (aux.shape[0], env.action_space.shape[0]))
    )
    split = reg.term_gradients(aux, actions)
    leaf = actions.clone().requires_grad_(True)
    total, _ = reg(aux, leaf)
    (whole,) = torch.autograd.grad(total, leaf)
    torch.testing.assert_close(split["l_sim"] + split["l_hap"], whole, rtol=1e-9, atol=1e-12)
    leaf = actions.clone().float().requires_grad_(True)
    centered = reg.adapted_via_points(aux.float(), leaf) - reg.prior_mean
    l_sim = reg.weights.lambda_sim * reg.similarity_loss(centered).mean()
    (expected,) = torch.autograd.grad(l_sim, leaf)
    scale = expected.abs().max().item()
    assert scale > 0 and split["l_hap"].abs().max() > 0
    torch.testing.assert_close(split["l_sim"].float(), expected, rtol=1e-3, atol=1e-4 * scale)


def test_actor_loss_gradient_norms_are_per_term_and_leave_the_random_streams_alone(
    dist_gprl_agent,
):
    """`RegularisedSAC.actor_loss_gradient_norms`: {} on an empty replay buffer; then one
    positive norm per actor-loss term the method uses (Q, L_sim, L_hap), the same for the
    same seed, and neither torch's nor NumPy's global generator moves (a resumed run logs the
    same values and trains the same)."""
    env, model, observations = dist_gprl_agent
    assert model.actor_loss_gradient_norms() == {}
    rng = np.random.default_rng(0)
    buffer = model.replay_buffer
    available = observations["state"].shape[0]  # an episode a collision ends is shorter
    for index in range(6):
        row = index % available
        obs = {key: value[row : row + 1].numpy() for key, value in observations.items()}
        action = rng.uniform(-1, 1, (1, env.action_space.shape[0])).astype(np.float32)
        buffer.add(obs, obs, action, np.array([1.0]), np.array([False]), [{}])
    torch_state, numpy_state = torch.get_rng_state(), np.random.get_state()  # noqa: NPY002
    first = model.actor_loss_gradient_norms(batch_size=16, seed=3)
    terms = {"grad_q", "grad_sim", "grad_hap", "hap_active_fraction"}
    assert terms <= set(first) <= terms | {"grad_hap_active"}
    assert all(np.isfinite(v) and v >= 0 for v in first.values()), first
    assert all(first[key] > 0 for key in ("grad_q", "grad_sim", "grad_hap")), first
    # the share of samples with a query outside C_safe, and their pull where there are any
    assert 0 <= first["hap_active_fraction"] <= 1
    assert ("grad_hap_active" in first) == (first["hap_active_fraction"] > 0)
    assert model.actor_loss_gradient_norms(batch_size=16, seed=3) == first
    assert torch.equal(torch.get_rng_state(), torch_state)
    after = np.random.get_state()  # noqa: NPY002
    assert np.array_equal(after[1], numpy_state[1]) and after[2] == numpy_state[2]
    buffer.reset()


def test_l_hap_gradient_rows_are_zero_exactly_where_the_hinged_sample_is_inside_c_safe(
    dist_gprl_agent,
):
    """What `distgprl.agents.gradient_norms` relies on holds for the v6–v7 hinge variant: a
    sample's L_hap gradient row (`term_gradients`) is 0 exactly where its own L_hap (the
    forward pass on it alone) is 0 — on a grid C_safe holding the whole trajectory with half
    the batch's via-points moved 2 m out of it (both sides). Under environment v8's L_hap as
    written (no hinge, the ci agent's own prior) no sample is without pull: every row of the
    real observations' gradient is nonzero, and L_hap is negative where the samples lie in
    C_safe."""
    env, model, observations = dist_gprl_agent
    aux = observations["aux"].double()
    actions = np.random.default_rng(7).uniform(-1, 1, (aux.shape[0], env.action_space.shape[0]))
    assert model.regulariser.hap_prior.hinge_step == 0.0  # the v8 default: as written
    rows = model.regulariser.term_gradients(aux, torch.as_tensor(actions))["l_hap"]
    assert np.all(rows.norm(dim=1).numpy() > 0)
    skill = small_skill()
    layout = build_action_layout(skill, V5_OPERATOR, get_method("dist-gprl"))
    axes = [np.arange(0.0, 1.01, 0.1), np.arange(-0.5, 0.51, 0.1), np.arange(-0.2, 0.71, 0.1)]
    c_safe = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    weights = RegulariserWeights(lambda_sim=0.0, lambda_hap=1.0)
    moved = aux_batch(skill, layout, batch=6).double()
    moved[3:, : skill.n_via_points * 6 : 6] += 2.0  # x of every via-point
    small = torch.as_tensor(
        0.01 * np.random.default_rng(8).uniform(-1, 1, (6, layout.points_per_step * 6))
    )
    hinged = ActorRegulariser(skill, layout, weights, hap_prior=HapPrior(c_safe, hinge_step=0.1))
    rows = hinged.term_gradients(moved, small)["l_hap"].norm(dim=1).numpy()
    alone = np.array([hinged(moved[i : i + 1], small[i : i + 1])[1]["l_hap"] for i in range(6)])
    np.testing.assert_array_equal(rows > 0, alone > 0)
    assert np.sum(alone == 0) == 3 and np.sum(alone > 0) == 3
    raw = ActorRegulariser(skill, layout, weights, hap_prior=HapPrior(c_safe, grid_step=0.1))
    split = raw.term_gradients(moved, small)
    rows = split["l_hap"].norm(dim=1).numpy()
    alone = np.array([raw(moved[i : i + 1], small[i : i + 1])[1]["l_hap"] for i in range(6)])
    assert np.all(rows > 0) and np.all(alone[:3] < 0) and np.all(alone[3:] > 1.0)
    # "outside C_safe" for the mechanism table: exactly the samples moved out of it
    np.testing.assert_array_equal(split["hap_outside"].numpy(), [False] * 3 + [True] * 3)


def test_active_hap_norms_average_over_the_samples_outside_c_safe():
    """`active_hap_norms` by hand: of three samples, two with a gradient (norms 3 and 5 per
    sample after the batch-size factor), one inside C_safe; none active -> only the share."""
    from distgprl.agents.gradient_norms import active_hap_norms

    gradient = torch.tensor([[3.0, 0.0], [0.0, 0.0], [3.0, 4.0]]) / 3  # batch-mean's gradient
    out = active_hap_norms(gradient, 3)
    assert out == pytest.approx({"hap_active_fraction": 2 / 3, "grad_hap_active": 4.0})
    assert active_hap_norms(gradient * 0, 3) == {"hap_active_fraction": 0.0}
    # with the outside flags (the raw soft-min pulls inside C_safe too): only flagged samples
    flagged = active_hap_norms(gradient, 3, torch.tensor([False, False, True]))
    assert flagged == pytest.approx({"hap_active_fraction": 1 / 3, "grad_hap_active": 5.0})


def test_a_signal_during_a_tensorboard_write_lands_after_the_write(tmp_path):
    """Ctrl-C while the training logger writes its TensorBoard records: every record of the
    dump is handed to the writer, then the KeyboardInterrupt is raised, and the writer
    still closes (its thread's queue count intact: no ``task_done() called too many times``
    traceback)."""
    import signal

    pytest.importorskip("tensorboard")
    # Python's own Ctrl-C handler, as in a command (a pytest-xdist worker ignores SIGINT)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        _interrupt_a_tensorboard_write(tmp_path)
    finally:
        signal.signal(signal.SIGINT, previous)


def _interrupt_a_tensorboard_write(tmp_path):
    import os
    import signal

    logger = training_logger(tmp_path / "tb")
    (board,) = logger.output_formats
    add_scalar = board.writer.add_scalar
    written: list[str] = []

    def add_scalar_and_interrupt(tag, *args, **kwargs):
        if not written:
            os.kill(os.getpid(), signal.SIGINT)
        written.append(tag)
        return add_scalar(tag, *args, **kwargs)

    board.writer.add_scalar = add_scalar_and_interrupt
    logger.record("train/a", 1.0)
    logger.record("train/b", 2.0)
    with pytest.raises(KeyboardInterrupt):
        logger.dump(1)
    assert written == ["train/a", "train/b"]
    logger.close()
    assert list((tmp_path / "tb").glob("events.out.tfevents.*"))
