"""The suite's floor (`distgprl.experiments.bench.floor`): the dispatch-mode clock sees exactly
the matrix products an update runs, forward and backward, with their exact FLOPs; a plain SAC
update of the paper's networks runs the products the algorithm needs and no others; the
floor's arithmetic is checkable by hand."""

from __future__ import annotations

import pytest
import torch

from distgprl.experiments.bench.floor import (
    MatrixProductClock,
    sac_update_matrix_products,
    suite_floor,
)
from distgprl.experiments.bench.sizes import run_spec


def test_clock_counts_linear_forward_and_backward_products():
    """nn.Linear(8, 4) on a (5, 8) input that needs its gradient: one addmm forward, two mm
    backward (input and weight gradients), 2 x 5 x 8 x 4 FLOPs each; a bmm (3, 2, 4) @ (3, 4, 6)
    adds 2 x 3 x 2 x 4 x 6; the element-wise ops in between are not counted."""
    torch.manual_seed(0)
    linear = torch.nn.Linear(8, 4)
    x = torch.randn(5, 8, requires_grad=True)
    with MatrixProductClock() as clock:
        linear(x).relu().square().sum().backward()
        torch.bmm(torch.randn(3, 2, 4), torch.randn(3, 4, 6))
    assert clock.calls == 4
    assert clock.flops == 3 * 2 * 5 * 8 * 4 + 2 * 3 * 2 * 4 * 6
    assert clock.seconds > 0
    # Outside the `with`, nothing is counted.
    linear(x).sum().backward()
    assert clock.calls == 4


def _sac_flops_per_sample(state: int, action: int, hidden: int) -> int:
    """Multiply-adds per batch sample of one SB3 SAC update, two hidden layers of ``hidden``,
    two critics, the actor loss through critics whose parameters are frozen."""
    latent = state * hidden + hidden * hidden  # actor's two hidden layers
    head = hidden * action  # mean or log-std head
    critic = (state + action) * hidden + hidden * hidden + hidden  # one Q network
    actor = latent + 2 * head  # actor forward, or its weight gradients
    return (
        # actor on observations and on next observations
        2 * actor
        # critics: target on next; on replay actions, forward + weight gradients;
        # on the actor's actions, forward + input gradients
        + 5 * 2 * critic
        # critic loss: input gradients of layers 2 and 3
        + 2 * (hidden * hidden + hidden)
        # actor loss: weight gradients, input gradients below the heads
        + actor
        + 2 * head
        + hidden * hidden
    )


def test_plain_sac_update_runs_the_products_of_the_algorithm():
    """On the paper preset's DCP model (batch 256, 256 x 256 networks): 49 products per update
    (26 addmm forward, 23 mm backward) and exactly the FLOPs of the SAC update's layers;
    they are part of the update's time (share in (0, 1)), the uninstrumented update costs less than
    the clocked one and ``non_product_ms`` is the rest; the regulariser is put back."""
    from stable_baselines3.common.logger import configure

    from distgprl.experiments.bench.sac_update import fill_replay_buffer
    from distgprl.experiments.factories import make_agent, make_env

    run = run_spec("dcp")
    env = make_env(run)
    try:
        model = make_agent(env, run)
        model.set_logger(configure(None, []))
        fill_replay_buffer(model, env, 300)
        regulariser = model.regulariser
        assert regulariser is not None
        result = sac_update_matrix_products(model, updates=2, warmup=1)
        assert model.regulariser is regulariser
        state = env.observation_space["state"].shape[0]
        action = env.action_space.shape[0]
    finally:
        env.close()
    assert result["calls_per_update"] == 49
    expected = 2 * 256 * _sac_flops_per_sample(state, action, 256)
    assert result["gflop_per_update"] * 1e9 == pytest.approx(expected, rel=1e-12)
    assert 0 < result["matrix_product_share"] < 1
    # The uninstrumented updates: their time holds the products; the rest is framework work.
    assert result["non_product_ms"] == pytest.approx(
        result["update_ms"] - result["matrix_products_ms"]
    )
    assert result["matrix_product_share"] == pytest.approx(
        result["matrix_products_ms"] / result["update_ms"]
    )
    assert result["update_ms"] < result["update_ms_with_clock"]
    assert 0 < result["matrix_products_ms"] < result["update_ms_with_clock"]


def test_suite_floor_by_hand():
    """Two tasks: 4 runs of 10 steps (2 before learning) at 0.5 s of physics per step and 3 s
    of products per update: 4 (10 x 0.5 + 8 x 3) = 116 s; 4 runs of 20 steps (5 before) at
    1 s: 4 (20 x 1 + 15 x 3) = 260 s; 376 s in all, half of it on two cores."""
    floor = suite_floor(
        3.0, {"a": 0.5, "b": 1.0}, {"a": 10, "b": 20}, {"a": 2, "b": 5}, {"a": 4, "b": 4}, 2
    )
    assert floor["cpu_hours"] == pytest.approx(376 / 3600)
    assert floor["hours_idle_cores"] == pytest.approx(188 / 3600)
    assert floor["per_task"]["a"]["physics_cpu_hours"] == pytest.approx(20 / 3600)
    assert floor["per_task"]["b"]["matrix_product_cpu_hours"] == pytest.approx(180 / 3600)
    # learning_starts beyond the run: no update, physics only
    alone = suite_floor(3.0, {"a": 0.5}, {"a": 10}, {"a": 50}, {"a": 1}, 1)
    assert alone["cpu_hours"] == pytest.approx(5 / 3600)
