"""Reference: the actor regulariser as it was before the speed rewrite (issue 29).

A verbatim copy of ``ActorRegulariser`` (distgprl/agents/regularisers.py at commit 6b92ebb,
renamed), kept only so that `test_regularisers.py` can check that the flat-matrix version
gives the same values and gradients. Not used by the package.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from distgprl.agents.regularisers import RegulariserWeights
from distgprl.safety.hap_filter import MovingObstacleFilter
from distgprl.skill.gp import GPSkill


class ReferenceActorRegulariser(nn.Module):
    """lambda_sim L_sim + lambda_hap L_hap for a batch of observations and actions.

    Args:
        skill: the task's GP skill (maps and demonstration via-points).
        layout: the environment's `ActionLayout` (indices, operators, scale, frozen rows).
        weights: the four weights; a zero weight skips its term entirely.
        hap_prior: a `HapPrior` (Eq. hap_compact), or None.
        n_similarity_samples: T, trajectory samples of Eq. sim_compact.
        n_hap_queries: N_q, positions sampled along the trajectory for L_hap.
        moving_filter: the environment's `MovingObstacleFilter` (``moving_obstacle_filter()``);
            with it, ``aux`` must end with the moving obstacles' anchors at the N via-point
            times (N x 3), and each query x_q uses C_safe without the points the obstacles
            block at x_q's time (anchor interpolated linearly between via-point times).
    """

    def __init__(
        self,
        skill: GPSkill,
        layout,
        weights: RegulariserWeights,
        hap_prior: nn.Module | None = None,
        n_similarity_samples: int = 50,
        n_hap_queries: int = 20,
        moving_filter: MovingObstacleFilter | None = None,
    ) -> None:
        super().__init__()
        self.weights = weights
        self.n_via_points = skill.n_via_points
        self.n_steps = layout.n_steps
        self.points_per_step = layout.points_per_step
        if weights.lambda_hap > 0 and hap_prior is None:
            raise ValueError("lambda_hap > 0 needs a hap_prior")
        self.hap_prior = hap_prior if weights.lambda_hap > 0 else None

        def buffer(name: str, value: np.ndarray, dtype=torch.float32) -> None:
            self.register_buffer(name, torch.as_tensor(np.asarray(value), dtype=dtype))

        mask = np.ones(layout.indices.shape)
        for index in layout.frozen:
            mask[layout.indices == index] = 0.0
        buffer("indices", layout.indices, torch.long)
        buffer("operators", layout.operators)
        buffer("scale", layout.scale)
        buffer("mask", mask)
        buffer("prior_mean", skill.prior_mean)
        tau = np.linspace(0.0, 1.0, n_similarity_samples)
        demo_centered = skill.via_points - skill.prior_mean
        buffer("velocity_map", skill.velocity_map(tau))
        buffer("acceleration_map", skill.acceleration_map(tau))
        buffer("demo_velocity", skill.velocity_map(tau) @ demo_centered)
        buffer("demo_acceleration", skill.acceleration_map(tau) @ demo_centered)
        hap_tau = np.linspace(0.0, 1.0, n_hap_queries)
        buffer("hap_map", skill.position_map(hap_tau))
        self.moving_filter = moving_filter if self.hap_prior is not None else None
        # Linear interpolation (N_q, N) of the anchors at the via-point times to the queries.
        via_times = np.asarray(skill.via_times, dtype=float)
        identity = np.eye(len(via_times))
        buffer(
            "anchor_map",
            np.stack(
                [np.interp(hap_tau, via_times, identity[j]) for j in range(len(via_times))], 1
            ),
        )

    def adapted_via_points(self, aux: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Gamma + Delta Gamma for a batch, shape (B, N, 6) (Eqs. transformed/updated)."""
        batch = aux.shape[0]
        n = self.n_via_points
        gamma = aux[:, : n * 6].reshape(batch, n, 6)
        step = aux[:, n * 6 : n * 6 + self.n_steps].argmax(dim=1)
        raw = actions.reshape(batch, self.points_per_step, 6) * self.scale
        # environment v5: one S_W per axis (the only change to the verbatim copy)
        delta = torch.einsum("baij,bja->bia", self.operators[step], raw)
        delta = delta * self.mask[step].unsqueeze(-1)
        index = self.indices[step].unsqueeze(-1).expand(-1, -1, 6)
        return gamma.scatter_add(1, index, delta)

    def similarity_loss(self, centered: torch.Tensor) -> torch.Tensor:
        """L_sim (Eq. sim_compact) for centered via-points (B, N, 6)."""
        velocity = torch.matmul(self.velocity_map, centered)  # (B, T, 6)
        acceleration = torch.matmul(self.acceleration_map, centered)
        cos = nn.functional.cosine_similarity(
            velocity, self.demo_velocity.expand_as(velocity), dim=-1
        )
        l1 = (acceleration - self.demo_acceleration).abs().sum(dim=-1)
        return self.weights.lambda_velocity * (1.0 - cos.mean(dim=1)) + (
            self.weights.lambda_acceleration * l1.mean(dim=1)
        )

    def forward(self, aux: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, dict]:
        """Total regularisation (scalar) and its logged terms."""
        terms: dict[str, float] = {}
        total = actions.new_zeros(())
        if self.weights.lambda_sim <= 0 and self.hap_prior is None:
            return total, terms
        centered = self.adapted_via_points(aux, actions) - self.prior_mean
        if self.weights.lambda_sim > 0:
            l_sim = self.similarity_loss(centered).mean()
            total = total + self.weights.lambda_sim * l_sim
            terms["l_sim"] = float(l_sim.detach())
        if self.hap_prior is not None:
            positions = (torch.matmul(self.hap_map, centered) + self.prior_mean)[..., :3]
            if self.moving_filter is None:
                l_hap = self.hap_prior.loss(positions)
            else:
                n = self.n_via_points
                start = n * 6 + self.n_steps
                if aux.shape[1] != start + n * 3:
                    raise ValueError(
                        f"aux has {aux.shape[1]} entries; the moving-obstacle filter needs "
                        f"{start + n * 3} (Gamma, step one-hot, anchors)"
                    )
                anchors = torch.matmul(self.anchor_map, aux[:, start:].reshape(-1, n, 3))
                l_hap = self.hap_prior.loss(positions, anchors, self.moving_filter)
            total = total + self.weights.lambda_hap * l_hap
            terms["l_hap"] = float(l_hap.detach())
        return total, terms
