"""The SAC update's framework cuts (issue 49, `distgprl.agents.update`) against the v5 update.

The replay sampler reproduces SB3's batches bit for bit and advances NumPy's global stream
the same way; the tanh-Gaussian sample equals SB3's distribution objects to float32
rounding; one whole regularised update from the same model, replay buffer and random
streams equals the v5 update (`tests/agents/_reference_sac.py`) to 1e-9 in float64.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch
from _reference_sac import reference_train
from stable_baselines3.common.logger import configure
from stable_baselines3.common.utils import polyak_update

from distgprl.agents.update import ReplaySampler, polyak_lerp, squashed_gaussian_sample


@pytest.fixture(scope="module")
def agent():
    """The ci preset's DCP dist-gprl agent with 300 real transitions in its buffer."""
    from distgprl.experiments.factories import make_agent, make_env
    from distgprl.identity import resolve_run

    torch.manual_seed(0)
    run = resolve_run("dcp", "dist-gprl", 0, "ci")
    env = make_env(run)
    model = make_agent(env, run)
    model.learning_starts = 300
    model.learn(300)
    model.set_logger(configure(None, []))
    yield model
    env.close()


def test_replay_sampler_draws_sb3s_batches_bit_for_bit(agent):
    buffer = agent.replay_buffer
    sampler = ReplaySampler(buffer)
    assert ReplaySampler.supports(buffer, None)
    for batch_size in (7, 64, 7):  # a new batch size rebinds the output tensors
        np.random.seed(batch_size)  # noqa: NPY002
        expected = buffer.sample(batch_size)
        state = np.random.get_state()  # noqa: NPY002
        np.random.seed(batch_size)  # noqa: NPY002
        got = sampler.sample(batch_size)
        after = np.random.get_state()  # noqa: NPY002
        assert after[0] == state[0] and np.array_equal(after[1], state[1])
        assert after[2:] == state[2:]
        for key in expected.observations:
            assert torch.equal(got.observations[key], expected.observations[key])
            assert torch.equal(got.next_observations[key], expected.next_observations[key])
        for field in ("actions", "dones", "rewards"):
            value, reference = getattr(got, field), getattr(expected, field)
            assert value.dtype == reference.dtype and torch.equal(value, reference), field
        assert got.discounts is None


def test_replay_sampler_follows_a_replaced_buffer_array(agent):
    """A buffer loaded from a checkpoint replaces its arrays: the sampler reads the new ones."""
    buffer = copy.deepcopy(agent.replay_buffer)
    sampler = ReplaySampler(buffer)
    sampler.sample(5)
    buffer.rewards = buffer.rewards + 1.0
    np.random.seed(1)  # noqa: NPY002
    expected = buffer.sample(5)
    np.random.seed(1)  # noqa: NPY002
    assert torch.equal(sampler.sample(5).rewards, expected.rewards)


def test_squashed_gaussian_sample_equals_sb3s_distribution(agent):
    observations = agent.replay_buffer.sample(128).observations
    torch.manual_seed(3)
    with torch.no_grad():
        expected_actions, expected_log_prob = agent.actor.action_log_prob(observations)
    state = torch.get_rng_state()
    torch.manual_seed(3)
    with torch.no_grad():
        mean, log_std, _ = agent.actor.get_action_dist_params(observations)
        actions, log_prob = squashed_gaussian_sample(mean, log_std)
    assert torch.equal(torch.get_rng_state(), state)  # the same draws
    torch.testing.assert_close(actions, expected_actions, rtol=0, atol=1e-6)
    torch.testing.assert_close(log_prob, expected_log_prob, rtol=1e-5, atol=1e-4)


def test_polyak_lerp_equals_sb3s_polyak_update():
    torch.manual_seed(0)
    params = [torch.randn(5, 3), torch.randn(4)]
    targets = [torch.randn(5, 3), torch.randn(4)]
    expected = [t.clone() for t in targets]
    polyak_update(params, expected, 0.005)
    polyak_lerp(params, targets, 0.005)
    for value, reference in zip(targets, expected, strict=True):
        torch.testing.assert_close(value, reference, rtol=1e-6, atol=1e-6)  # float32 ulps


def _double(model) -> None:
    """The model, its optimizers' state and its replay buffer in float64."""
    model.policy.double()
    model.log_ent_coef.data = model.log_ent_coef.data.double()
    for optimizer in (model.actor.optimizer, model.critic.optimizer, model.ent_coef_optimizer):
        for state in optimizer.state.values():
            for key, value in state.items():
                if torch.is_tensor(value) and value.is_floating_point() and key != "step":
                    state[key] = value.double()
    buffer = model.replay_buffer
    for observations in (buffer.observations, buffer.next_observations):
        for key in observations:
            observations[key] = observations[key].astype(np.float64)
    for name in ("actions", "rewards", "dones", "timeouts"):
        setattr(buffer, name, getattr(buffer, name).astype(np.float64))


def _parameters(model) -> torch.Tensor:
    return torch.cat(
        [torch.nn.utils.parameters_to_vector(model.policy.parameters()), model.log_ent_coef]
    ).detach()


def test_one_update_equals_the_v5_update_in_float64(agent, monkeypatch):
    """Two updates (regularised actor loss, learned alpha) from one state, one by the v5 code
    and one by the current code: every parameter of actor, critics, target critics and alpha
    to 1e-9, the logged losses to 1e-9, and the random streams left in the same state.
    (SB3 casts observations to float32 before the networks: here they stay float64.)"""
    import stable_baselines3.common.policies as policies

    monkeypatch.setattr(policies, "preprocess_obs", lambda obs, *args, **kwargs: obs)
    model = copy.deepcopy(agent)
    _double(model)
    model.train(gradient_steps=1, batch_size=32)  # Adam's moments are non-zero below
    assert model.regulariser is not None and model.ent_coef_optimizer is not None
    start = copy.deepcopy(model)
    results = {}
    for name, update in (("v5", reference_train), ("v6", type(model).train)):
        candidate = copy.deepcopy(start)
        np.random.seed(7)  # noqa: NPY002
        torch.manual_seed(7)
        update(candidate, 2, 32)
        results[name] = (
            _parameters(candidate),
            dict(candidate.last_regulariser_terms),
            torch.get_rng_state(),
            np.random.get_state()[1].copy(),  # noqa: NPY002
        )
    (new, new_terms, new_torch, new_numpy) = results["v6"]
    (old, old_terms, old_torch, old_numpy) = results["v5"]
    assert new.dtype == torch.float64
    assert not torch.equal(new, _parameters(start))  # the update moved the parameters
    torch.testing.assert_close(new, old, rtol=0, atol=1e-9)
    assert new_terms.keys() == old_terms.keys() and {"l_sim", "l_hap"} <= new_terms.keys()
    for key, value in new_terms.items():
        assert value == pytest.approx(old_terms[key], rel=1e-9, abs=1e-12), key
    assert torch.equal(new_torch, old_torch) and np.array_equal(new_numpy, old_numpy)


def test_one_update_in_float32_stays_within_rounding_of_the_v5_update(agent):
    """The training precision: the logged losses of one update to 1e-5 (relative)."""
    results = {}
    for name, update in (("v5", reference_train), ("v6", type(agent).train)):
        candidate = copy.deepcopy(agent)
        np.random.seed(11)  # noqa: NPY002
        torch.manual_seed(11)
        update(candidate, 1, 64)
        results[name] = dict(candidate.last_regulariser_terms)
    for key, value in results["v6"].items():
        assert value == pytest.approx(results["v5"][key], rel=1e-5, abs=1e-6), key


def test_training_mode_is_set_on_every_module(agent):
    """The cached training-flag setter reaches every module, as SB3's recursive one does, and
    a deep copy's setter its own modules."""
    from distgprl.agents.sac import RegularisedSACPolicy

    assert isinstance(agent.policy, RegularisedSACPolicy)
    from stable_baselines3.sac.policies import SACPolicy

    agent.policy.set_training_mode(False)
    model = copy.deepcopy(agent)
    reference = copy.deepcopy(agent)
    for mode in (True, False, True):
        model.policy.set_training_mode(mode)
        # SB3's own (SACPolicy's: actor, critic, the policy; the target critic left alone)
        SACPolicy.set_training_mode(reference.policy, mode)
        flags = [m.training for m in model.policy.modules()]
        assert flags == [m.training for m in reference.policy.modules()]
        assert not any(m.training for m in model.critic_target.modules())
    assert not any(module.training for module in agent.policy.modules())
