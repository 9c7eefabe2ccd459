"""A trained SAC actor's deterministic action evaluated with NumPy (`NumpyActor`): for one
observation the torch call overhead dominates, so evaluation and the bench run the same
weights as three small matrix products."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["NumpyActor"]


class NumpyActor:
    """The deterministic action of an SB3 SAC actor, evaluated with NumPy (float32).

    SB3's deterministic SAC action is ``tanh(mu(latent_pi(state)))``; for one observation the
    torch call overhead dominates, so the same weights are run as three small matrix products.
    Only MLP actors with ReLU activations and no gSDE are supported.

    Args:
        actor: ``model.actor`` of a `RegularisedSAC` (weights are copied, not shared).
    """

    def __init__(self, actor: Any) -> None:
        from torch import nn

        if getattr(actor, "use_sde", False):
            raise ValueError("gSDE actors are not supported")
        self.layers: list[tuple[np.ndarray, np.ndarray]] = []
        for module in actor.latent_pi:
            if isinstance(module, nn.Linear):
                self.layers.append(self._weights(module))
            elif not isinstance(module, nn.ReLU):
                raise ValueError(f"unsupported actor layer {type(module).__name__}")
        self.mu = self._weights(actor.mu)

    @staticmethod
    def _weights(linear: Any) -> tuple[np.ndarray, np.ndarray]:
        weight = linear.weight.detach().cpu().numpy().astype(np.float32)
        bias = linear.bias.detach().cpu().numpy().astype(np.float32)
        return np.ascontiguousarray(weight.T), bias

    def __call__(self, state: np.ndarray) -> np.ndarray:
        """Action in [-1, 1] for one ``state`` (D,) or a batch (B, D)."""
        x = np.asarray(state, dtype=np.float32)
        for weight, bias in self.layers:
            x = x @ weight
            x += bias
            np.maximum(x, 0.0, out=x)
        weight, bias = self.mu
        x = x @ weight
        x += bias
        return np.tanh(x, out=x)
