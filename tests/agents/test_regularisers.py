"""ActorRegulariser (flat matrix products) against the pre-rewrite per-window implementation.

`_reference_regularisers.ReferenceActorRegulariser` is the implementation before issue 29
(one bmm, scatter and per-axis matmul per term). On random batches of the real shapes
(B = 256, 15 via-points, T = 50, N_q = 20; windowed, global and frozen layouts; every step)
the total, each logged term and the gradient w.r.t. the actions agree to 1e-9 in float64.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch
from _reference_regularisers import ReferenceActorRegulariser
from test_sac import QuadraticPrior, small_skill

from distgprl.adaptation.layout import build_action_layout
from distgprl.agents.regularisers import ActorRegulariser, RegulariserWeights
from distgprl.config_types import EnvConfig
from distgprl.methods import get_method
from distgprl.safety.hap_filter import MovingObstacleFilter
from distgprl.safety.hap_loss import HapPrior
from distgprl.safety.shapes import Box

# v5's operator and fixed scales: these tests check the plumbing, not the v6 reading
# (tests/adaptation/test_layout.py checks the Table I operator and the reach rule).
V5_OPERATOR = EnvConfig(covariance_scale="signal", action_scale_rule="fixed")

BATCH = 256
# Every layout a regularised method uses (and GPRL's frozen TC via-point).
LAYOUTS = [
    ("dist-gprl", ()),
    ("dist-gprl-nocov", ()),
    ("dist-gprl-global", ()),
    ("gprl-d", ()),
    ("gprl-h", ()),
    ("dist-gprl", (6,)),
]


def _c_safe() -> np.ndarray:
    axes = [np.arange(0.2, 0.81, 0.1), np.arange(-0.4, 0.41, 0.1), np.arange(0.0, 0.51, 0.1)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def _moving_filter() -> MovingObstacleFilter:
    box = (Box("cube", np.zeros(3), np.eye(3), np.full(3, 0.05), True),)
    return MovingObstacleFilter(box, np.zeros(3), np.full(3, 0.02), margin=0.03)


def _batch(skill, layout, rng: np.random.Generator, anchors: bool):
    """aux (B, N*6 + S [+ N*3]) with random via-points, steps and anchors; actions (B, A)."""
    n = skill.n_via_points
    gamma = skill.via_points[None] + rng.normal(0.0, 0.03, (BATCH, n, 6))
    one_hot = np.eye(layout.n_steps)[rng.integers(0, layout.n_steps, BATCH)]
    parts = [gamma.reshape(BATCH, -1), one_hot]
    if anchors:
        path = skill.via_points[None, :, :3] + rng.normal(0.0, 0.1, (BATCH, 1, 3))
        parts.append(path.reshape(BATCH, -1))
    aux = torch.as_tensor(np.concatenate(parts, 1), dtype=torch.float64)
    actions = rng.uniform(-1.0, 1.0, (BATCH, layout.points_per_step * 6))
    return aux, torch.as_tensor(actions, dtype=torch.float64)


def _evaluate(module, aux, actions):
    """Total, terms and the gradient times B (each sample's own gradient: the total is a
    batch mean, so 1e-9 on this is 1e-9 per sample, not per 1/B of it)."""
    leaf = actions.clone().requires_grad_(True)
    total, terms = module(aux, leaf)
    total.backward()
    return float(total.detach()), terms, leaf.grad.numpy() * len(leaf)


def _pair(method, frozen, weights, hap, moving):
    skill = small_skill()
    layout = build_action_layout(skill, V5_OPERATOR, get_method(method), frozen=frozen)
    prior = HapPrior(_c_safe(), dtype=torch.float64) if hap else None
    kwargs = dict(hap_prior=prior, moving_filter=_moving_filter() if moving else None)
    new = ActorRegulariser(skill, layout, weights, **kwargs).double()
    old = ReferenceActorRegulariser(skill, layout, _as_reference(weights, new), **kwargs).double()
    return skill, layout, new, old


def _as_reference(weights, new):
    """The reference predates environment v5's relative L1 term: give it lambda_a already
    divided by the demonstration's mean L1 acceleration."""
    return replace(weights, lambda_acceleration=new.acceleration_weight)


@pytest.mark.parametrize(("method", "frozen"), LAYOUTS)
@pytest.mark.parametrize(
    ("lambda_sim", "lambda_hap", "moving"),
    [(0.5, 0.0, False), (0.0, 0.2, False), (0.5, 0.2, False), (0.5, 0.2, True)],
)
def test_terms_and_action_gradients_equal_the_reference(
    method, frozen, lambda_sim, lambda_hap, moving
):
    """L_sim alone, L_hap alone (static and moving-filtered C_safe) and both: the total, the
    logged l_sim / l_hap and B d total / d actions equal the reference to 1e-9 (float64)."""
    weights = RegulariserWeights(lambda_sim=lambda_sim, lambda_hap=lambda_hap)
    skill, layout, new, old = _pair(method, frozen, weights, lambda_hap > 0, moving)
    aux, actions = _batch(skill, layout, np.random.default_rng(0), anchors=moving)
    total, terms, grad = _evaluate(new, aux, actions)
    ref_total, ref_terms, ref_grad = _evaluate(old, aux, actions)
    assert terms.keys() == ref_terms.keys() and len(terms) == (lambda_sim > 0) + (lambda_hap > 0)
    assert total == pytest.approx(ref_total, abs=1e-9) and abs(ref_total) > 1e-3
    for key in terms:
        assert terms[key] == pytest.approx(ref_terms[key], abs=1e-9), key
    scale = np.abs(ref_grad).max()
    assert scale > 1e-5
    # 1e-9 absolute, and also relative to the largest entry (the gradients can be small).
    np.testing.assert_allclose(grad, ref_grad, rtol=0, atol=1e-9 * min(scale, 1.0))


@pytest.mark.parametrize(("method", "frozen"), [("dist-gprl", ()), ("dist-gprl-global", ())])
def test_a_generic_prior_module_goes_through_autograd_and_equals_the_reference(method, frozen):
    """A prior that is not a `HapPrior` (a module with a differentiable ``loss(x)``) takes the
    autograd path: total, terms and gradient equal the reference to 1e-9 (float64)."""
    skill = small_skill()
    layout = build_action_layout(skill, V5_OPERATOR, get_method(method), frozen=frozen)
    weights = RegulariserWeights(lambda_sim=0.5, lambda_hap=0.2)
    prior = QuadraticPrior().double()
    new = ActorRegulariser(skill, layout, weights, hap_prior=prior).double()
    old = ReferenceActorRegulariser(
        skill, layout, _as_reference(weights, new), hap_prior=prior
    ).double()
    aux, actions = _batch(skill, layout, np.random.default_rng(3), anchors=False)
    total, terms, grad = _evaluate(new, aux, actions)
    ref_total, ref_terms, ref_grad = _evaluate(old, aux, actions)
    assert total == pytest.approx(ref_total, abs=1e-9)
    assert terms == pytest.approx(ref_terms, abs=1e-9) and set(terms) == {"l_sim", "l_hap"}
    np.testing.assert_allclose(grad, ref_grad, rtol=0, atol=1e-9 * np.abs(ref_grad).max())


def test_under_no_grad_the_value_is_the_same_and_carries_no_graph():
    """The fused path under ``torch.no_grad()``: same value, no graph attached."""
    weights = RegulariserWeights()
    skill, layout, new, _ = _pair("dist-gprl", (), weights, True, True)
    aux, actions = _batch(skill, layout, np.random.default_rng(4), anchors=True)
    with torch.no_grad():
        quiet, _ = new(aux, actions.clone().requires_grad_(True))
    assert not quiet.requires_grad
    loud, _ = new(aux, actions.clone().requires_grad_(True))
    assert loud.requires_grad and float(loud.detach()) == float(quiet)


@pytest.mark.parametrize(("method", "frozen"), LAYOUTS)
def test_readout_equals_the_per_window_maps(method, frozen):
    """`readout` (axis-major, (6, B, Q)) equals V, A (minus the demo's) and H applied to the
    adapted via-points of the reference (`adapted_via_points`, scatter of S_W (scale * a)),
    for every step."""
    weights = RegulariserWeights(lambda_sim=0.5, lambda_hap=0.0)
    skill, layout, new, old = _pair(method, frozen, weights, False, False)
    aux, actions = _batch(skill, layout, np.random.default_rng(1), anchors=False)
    centered = old.adapted_via_points(aux, actions) - old.prior_mean
    out = new.readout(aux, actions)
    t = old.velocity_map.shape[0]
    expected = [
        old.velocity_map @ centered,
        old.acceleration_map @ centered - old.demo_acceleration,
        (old.hap_map @ centered + old.prior_mean)[..., :3],
    ]
    assert out.shape == (6, BATCH, 2 * t + old.hap_map.shape[0])
    parts = [out[:, :, :t], out[:, :, t : 2 * t], out[:3, :, 2 * t :]]
    for part, reference in zip(parts, expected, strict=True):
        np.testing.assert_allclose(part.permute(1, 2, 0), reference, rtol=0, atol=1e-10)


def test_float32_regulariser_agrees_with_the_reference_to_float_precision():
    """In training's float32 (buffers as built), total and gradient agree to ~1e-5 relative."""
    skill = small_skill()
    layout = build_action_layout(skill, V5_OPERATOR, get_method("dist-gprl"))
    weights = RegulariserWeights()
    prior = HapPrior(_c_safe())
    new = ActorRegulariser(skill, layout, weights, hap_prior=prior)
    old = ReferenceActorRegulariser(skill, layout, _as_reference(weights, new), hap_prior=prior)
    aux, actions = _batch(skill, layout, np.random.default_rng(2), anchors=False)
    results = [_evaluate(m, aux.float(), actions.float()) for m in (new, old)]
    assert results[0][0] == pytest.approx(results[1][0], rel=1e-5)
    scale = np.abs(results[1][2]).max()
    np.testing.assert_allclose(results[0][2], results[1][2], rtol=0, atol=1e-5 * scale)


def test_acceleration_term_is_the_relative_l1_error():
    """Environment v5: Eq. sim_compact's L1 term is divided by the demonstration's own mean
    L1 acceleration (1/T) sum_t |acc_demo(t)|_1, so L_sim of adapted via-points equals
    lambda_v (1 - mean cos) + lambda_a mean |acc' - acc_demo|_1 / mean |acc_demo|_1; and a
    demonstration with twice the motion, adapted twice as much, has the same L_sim (both
    terms are dimensionless)."""
    skill = small_skill()
    layout = build_action_layout(skill, V5_OPERATOR, get_method("dist-gprl"))
    weights = RegulariserWeights(lambda_sim=0.5, lambda_hap=0.0, lambda_acceleration=0.7)
    module = ActorRegulariser(skill, layout, weights).double()
    tau = np.linspace(0.0, 1.0, 50)
    demo = skill.via_points - skill.prior_mean
    reference = np.abs(skill.acceleration_map(tau) @ demo).sum(1).mean()
    assert module.acceleration_reference == pytest.approx(reference, rel=1e-9)
    rng = np.random.default_rng(4)
    adapted = demo[None] + rng.normal(0.0, 0.02, (8, *demo.shape))
    velocity = np.einsum("tn,bnj->btj", skill.velocity_map(tau), adapted)
    demo_velocity = skill.velocity_map(tau) @ demo
    cos = (velocity * demo_velocity).sum(-1) / (
        np.linalg.norm(velocity, axis=-1) * np.linalg.norm(demo_velocity, axis=-1)
    )
    error = np.einsum("tn,bnj->btj", skill.acceleration_map(tau), adapted - demo[None])
    expected = (1.0 - cos.mean(1)) + 0.7 * np.abs(error).sum(-1).mean(1) / reference
    value = module.similarity_loss(torch.as_tensor(adapted)).numpy()
    np.testing.assert_allclose(value, expected, rtol=1e-5)
    doubled = replace(skill, via_points=skill.prior_mean + 2.0 * demo)
    module2 = ActorRegulariser(doubled, layout, weights).double()
    assert module2.acceleration_reference == pytest.approx(2.0 * reference, rel=1e-9)
    value2 = module2.similarity_loss(torch.as_tensor(2.0 * adapted)).numpy()
    np.testing.assert_allclose(value2, value, rtol=1e-6)
