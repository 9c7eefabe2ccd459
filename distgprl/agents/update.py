"""The framework work of a SAC update cut down (issue 49), for `distgprl.agents.sac.RegularisedSAC`.

Each piece replaces a part of stable-baselines3's update with fewer torch operations and no
new allocation, on the same random streams:

- `ReplaySampler`: the replay sample drawn into preallocated tensors (``index_select`` from
  tensors sharing the buffer's memory), with the same two ``np.random.randint`` draws as
  ``DictReplayBuffer.sample`` (so the global NumPy stream advances exactly as before) and the
  same values bit for bit.
- `squashed_gaussian_sample`: the actor's reparameterised tanh-Gaussian action and its
  log-probability from the noise itself (``-eps^2 / 2 - log sigma``), without building a
  ``torch.distributions.Normal`` and recomputing ``(x - mu)^2 / (2 sigma^2)``; the same noise
  draw (``empty().normal_()`` as ``Normal.rsample``), equal to SB3's to float rounding.
- `polyak_lerp`: the target critic's soft update as one ``_foreach_lerp_`` (SB3: a ``mul_``
  and an ``add`` per tensor); equal to float rounding.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.type_aliases import DictReplayBufferSamples

__all__ = ["ReplaySampler", "polyak_lerp", "squashed_gaussian_sample"]

#: SB3's ``SquashedDiagGaussianDistribution`` epsilon in log(1 - tanh^2 + eps).
SQUASH_EPSILON = 1e-6

_HALF_LOG_TWO_PI = 0.5 * math.log(2.0 * math.pi)


class ReplaySampler:
    """Replay batches of an SB3 ``DictReplayBuffer`` gathered into preallocated tensors.

    The tensors of one batch are overwritten by the next call: use a batch before sampling
    again (as an update does). Rebuilt by itself when the buffer's arrays change (a replay
    buffer loaded from a checkpoint). Only the plain buffer (no ``optimize_memory_usage``, no
    ``VecNormalize``) is supported; `supports` tells.
    """

    def __init__(self, buffer: Any) -> None:
        self.buffer = buffer
        self._arrays: tuple[np.ndarray, ...] = ()
        self._batch = -1

    @staticmethod
    def supports(buffer: Any, vec_normalize_env: Any) -> bool:
        """Whether ``buffer`` is a plain dict replay buffer this sampler reproduces."""
        return (
            vec_normalize_env is None
            and isinstance(getattr(buffer, "observations", None), dict)
            and not getattr(buffer, "optimize_memory_usage", False)
            and str(getattr(buffer, "device", "cpu")) == "cpu"
        )

    def _bind(self, batch_size: int) -> None:
        """Flat torch views of the buffer's arrays and the output tensors of a batch."""
        buffer = self.buffer
        keys = list(buffer.observations)
        arrays = (
            *(buffer.observations[k] for k in keys),
            *(buffer.next_observations[k] for k in keys),
            buffer.actions,
            buffer.rewards,
            buffer.dones,
            buffer.timeouts,
        )
        rows = buffer.buffer_size * buffer.n_envs

        def flat(array: np.ndarray) -> th.Tensor:
            return th.from_numpy(array).reshape(rows, -1)

        self._keys = keys
        self._views = [flat(a) for a in arrays]
        self._out = [th.empty((batch_size, v.shape[1]), dtype=v.dtype) for v in self._views]
        self._arrays = arrays
        self._batch = batch_size

    def _current(self, batch_size: int) -> bool:
        buffer = self.buffer
        arrays = self._arrays
        if self._batch != batch_size or not arrays:
            return False
        keys = self._keys
        n = len(keys)
        return (
            all(arrays[i] is buffer.observations[k] for i, k in enumerate(keys))
            and all(arrays[n + i] is buffer.next_observations[k] for i, k in enumerate(keys))
            and arrays[2 * n] is buffer.actions
            and arrays[2 * n + 1] is buffer.rewards
            and arrays[2 * n + 2] is buffer.dones
            and arrays[2 * n + 3] is buffer.timeouts
        )

    def sample(self, batch_size: int) -> DictReplayBufferSamples:
        """A batch as ``DictReplayBuffer.sample(batch_size)`` returns it (same draws, values)."""
        buffer = self.buffer
        if not self._current(batch_size):
            self._bind(batch_size)
        upper_bound = buffer.buffer_size if buffer.full else buffer.pos
        # SB3's two draws from NumPy's global stream, in its order (seeded by SB3's set_random_seed)
        batch_inds = np.random.randint(0, upper_bound, size=batch_size)  # noqa: NPY002
        env_indices = np.random.randint(0, high=buffer.n_envs, size=(batch_size,))  # noqa: NPY002
        rows = th.from_numpy(batch_inds * buffer.n_envs + env_indices)
        for view, out in zip(self._views, self._out, strict=True):
            th.index_select(view, 0, rows, out=out)
        n = len(self._keys)
        observations = dict(zip(self._keys, self._out[:n], strict=True))
        next_observations = dict(zip(self._keys, self._out[n : 2 * n], strict=True))
        actions, rewards, dones, timeouts = self._out[2 * n :]
        # SB3: dones * (1 - timeouts) (only dones that are not time-outs), (B, 1)
        return DictReplayBufferSamples(
            observations=observations,
            actions=actions,
            next_observations=next_observations,
            dones=dones * (1 - timeouts),
            rewards=rewards,
        )


def squashed_gaussian_sample(mean: th.Tensor, log_std: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
    """A reparameterised tanh(N(mean, exp(log_std)^2)) action (B, A) and its log-probability
    (B,), as SB3's ``SquashedDiagGaussianDistribution.log_prob_from_params``.

    log pi(a) = sum_i [-eps_i^2 / 2 - log sigma_i - log(2 pi) / 2 - log(1 - a_i^2 + 1e-6)],
    with eps the standard-normal draw: the Gaussian's log-density at mean + eps sigma written
    with eps itself (SB3 recomputes (x - mean)^2 / (2 sigma^2), which is eps^2 / 2 up to
    rounding and whose gradients w.r.t. mean and sigma are zero up to rounding).
    """
    noise = th.empty_like(mean).normal_()  # torch.distributions.Normal.rsample's draw
    std = log_std.exp()
    actions = th.tanh(mean + noise * std)
    log_prob = (noise.square().mul_(-0.5) - log_std).sum(dim=1)
    log_prob = log_prob - actions.shape[1] * _HALF_LOG_TWO_PI
    log_prob = log_prob - th.log(1 - actions.square() + SQUASH_EPSILON).sum(dim=1)
    return actions, log_prob


def polyak_lerp(params: list[th.Tensor], targets: list[th.Tensor], tau: float) -> None:
    """targets <- (1 - tau) targets + tau params, in place, one foreach op (no autograd)."""
    if targets:
        with th.no_grad():
            th._foreach_lerp_(targets, params, tau)
