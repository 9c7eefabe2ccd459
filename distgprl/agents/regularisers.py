"""The actor-loss regularisers of Dist-GPRL in torch (paper §IV-B, Eq. actor_final_compact).

Both terms are functions of the *actor's sampled action*: the action is mapped to
adapted via-points exactly as the environment does (scale, S_W, frozen rows), and the
adapted trajectory is read through the GP's linear maps, so gradients reach the actor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from distgprl.envs.adaptation import ActionLayout
from distgprl.safety.hap import MovingObstacleFilter
from distgprl.skill.gp import GPSkill


@dataclass(frozen=True)
class RegulariserWeights:
    """lambda_sim, lambda_hap (Eq. actor_final_compact) and lambda_v, lambda_a (Eq. sim_compact)."""

    lambda_sim: float = 0.5
    lambda_hap: float = 0.2
    lambda_velocity: float = 1.0
    lambda_acceleration: float = 0.05


class ActorRegulariser(nn.Module):
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
        layout: ActionLayout,
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
        self._build_flat_maps()

    def _build_flat_maps(self) -> None:
        """The whole action -> (velocity, acceleration, positions) map as one matrix.

        With c = Gamma - mu (B, N*6, flat) and the step's raw action a (B, A_v*6), the adapted
        centered via-points are c + a D_s (Eqs. transformed/updated: scale, S_W, frozen rows,
        scatter onto the window), and every read-out of the trajectory is linear in them:
        ``out = [c, onehot(s) (x) a] @ [[W], [D_0 W], ..., [D_{S-1} W]] + bias`` with
        W = [V (x) I_6 | A (x) I_6 | H (x) I_6[:, :3]] (T*6 + T*6 + N_q*3 columns). The bias
        holds -A Gamma_demo_c and mu[:3]. Products are taken in float64 from the module's own
        (float32) buffers, so they are exact images of the maps the per-window code applied.
        """
        f64 = torch.float64
        n, steps, per_step = self.n_via_points, self.n_steps, self.points_per_step
        eye6 = torch.eye(6, dtype=f64)
        blocks = [
            torch.kron(self.velocity_map.to(f64).T.contiguous(), eye6),  # (N*6, T*6)
            torch.kron(self.acceleration_map.to(f64).T.contiguous(), eye6),
            torch.kron(
                self.hap_map.to(f64).T.contiguous(), eye6[:, :3].contiguous()
            ),  # (N*6, N_q*3)
        ]
        readout = torch.cat(blocks, dim=1)
        self._n_velocity = blocks[0].shape[1]
        self._n_acceleration = blocks[1].shape[1]
        selection = torch.zeros(steps, per_step, n, dtype=f64)  # window row p -> via-point
        selection.scatter_(2, self.indices.unsqueeze(-1), 1.0)
        # M_s[p', v] = sum_p S_W[s, p, p'] mask[s, p] [indices[s, p] = v]  (A_v, N)
        gather = torch.einsum(
            "spq,sp,spv->sqv", self.operators.to(f64), self.mask.to(f64), selection
        )
        action_maps = torch.stack(
            [torch.kron(gather[s], torch.diag(self.scale.to(f64))) @ readout for s in range(steps)]
        ).reshape(steps * per_step * 6, -1)  # (S*A_v*6, out)
        bias = torch.zeros(readout.shape[1], dtype=f64)
        bias[
            self._n_velocity : self._n_velocity + self._n_acceleration
        ] = -self.demo_acceleration.to(f64).reshape(-1)
        bias[self._n_velocity + self._n_acceleration :] = self.prior_mean.to(f64)[:3].repeat(
            self.hap_map.shape[0]
        )
        demo_velocity = self.demo_velocity.to(f64)
        self.register_buffer("flat_map", torch.cat([readout, action_maps]), persistent=False)
        self.register_buffer("flat_bias", bias, persistent=False)
        self.register_buffer(
            "demo_direction",
            demo_velocity / demo_velocity.norm(dim=-1, keepdim=True).clamp_min(1e-8),
            persistent=False,
        )
        self._cast: dict[tuple, tuple[torch.Tensor, ...]] = {}

    def _flat(self, like: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """flat_map, flat_bias, demo_direction in ``like``'s dtype and device (cached)."""
        key = (like.dtype, like.device, self.flat_map.device, self.flat_map.data_ptr())
        cached = self._cast.get(key)
        if cached is None:
            cached = tuple(
                t.to(device=like.device, dtype=like.dtype)
                for t in (self.flat_map, self.flat_bias, self.demo_direction)
            )
            self._cast = {key: cached}
        return cached

    def readout(self, aux: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Velocities, accelerations minus the demo's, positions of the adapted trajectory.

        One matrix product (see `_build_flat_maps`); shape (B, T*6 + T*6 + N_q*3), flattened
        per sample as (T, 6), (T, 6), (N_q, 3), m/s (normalised time), m/s^2, m.
        """
        batch = aux.shape[0]
        n = self.n_via_points
        flat_map, flat_bias, _ = self._flat(actions)
        centered = aux[:, : n * 6] - self.prior_mean.to(actions.dtype).repeat(n)
        step = aux[:, n * 6 : n * 6 + self.n_steps].argmax(dim=1)
        one_hot = nn.functional.one_hot(step, self.n_steps).to(actions.dtype)
        selected = (one_hot.unsqueeze(-1) * actions.unsqueeze(1)).reshape(batch, -1)
        return torch.addmm(
            flat_bias, torch.cat([centered.to(actions.dtype), selected], 1), flat_map
        )

    def adapted_via_points(self, aux: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Gamma + Delta Gamma for a batch, shape (B, N, 6) (Eqs. transformed/updated)."""
        batch = aux.shape[0]
        n = self.n_via_points
        gamma = aux[:, : n * 6].reshape(batch, n, 6)
        step = aux[:, n * 6 : n * 6 + self.n_steps].argmax(dim=1)
        raw = actions.reshape(batch, self.points_per_step, 6) * self.scale
        delta = torch.bmm(self.operators[step], raw) * self.mask[step].unsqueeze(-1)
        index = self.indices[step].unsqueeze(-1).expand(-1, -1, 6)
        return gamma.scatter_add(1, index, delta)

    def similarity_loss(self, centered: torch.Tensor) -> torch.Tensor:
        """L_sim (Eq. sim_compact) for centered via-points (B, N, 6), per sample (B,)."""
        velocity = torch.matmul(self.velocity_map, centered)  # (B, T, 6)
        acceleration = torch.matmul(self.acceleration_map, centered)
        cos = nn.functional.cosine_similarity(
            velocity, self.demo_velocity.expand_as(velocity), dim=-1
        )
        l1 = (acceleration - self.demo_acceleration).abs().sum(dim=-1)
        return self.weights.lambda_velocity * (1.0 - cos.mean(dim=1)) + (
            self.weights.lambda_acceleration * l1.mean(dim=1)
        )

    def _similarity_from_readout(self, out: torch.Tensor) -> torch.Tensor:
        """Batch mean of L_sim (Eq. sim_compact) from `readout`'s output, a scalar."""
        batch = out.shape[0]
        n_v, n_a = self._n_velocity, self._n_acceleration
        _, _, direction = self._flat(out)
        velocity = out[:, :n_v].reshape(batch, -1, 6)  # (B, T, 6)
        # cos = v . d / (|v| |d|), d/|d| precomputed (torch's cosine_similarity clamps the
        # norms at 1e-8 likewise).
        cos = (velocity * direction).sum(-1) / velocity.square().sum(-1).sqrt().clamp_min(1e-8)
        l1 = out[:, n_v : n_v + n_a].abs().sum()  # sum over B, T and the 6 axes
        samples = velocity.shape[1] * batch
        return self.weights.lambda_velocity * (1.0 - cos.sum() / samples) + (
            self.weights.lambda_acceleration * l1 / samples
        )

    def forward(self, aux: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, dict]:
        """Total regularisation (scalar) and its logged terms."""
        terms: dict[str, float] = {}
        total = actions.new_zeros(())
        if self.weights.lambda_sim <= 0 and self.hap_prior is None:
            return total, terms
        out = self.readout(aux, actions)
        if self.weights.lambda_sim > 0:
            l_sim = self._similarity_from_readout(out)
            total = total + self.weights.lambda_sim * l_sim
            terms["l_sim"] = float(l_sim.detach())
        if self.hap_prior is not None:
            start = self._n_velocity + self._n_acceleration
            positions = out[:, start:].reshape(out.shape[0], -1, 3)  # (B, N_q, 3)
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
