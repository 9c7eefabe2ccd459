"""The actor-loss regularisers of Dist-GPRL (paper §IV-B, Eq. actor_final_compact): a torch
module whose fused path computes the losses and their gradient in NumPy.

Both terms are functions of the *actor's sampled action*: the action is mapped to
adapted via-points exactly as the environment does (scale, S_W, frozen rows), and the
adapted trajectory is read through the GP's linear maps, so gradients reach the actor.

Speed (issue 29): the whole action -> (velocity, acceleration, L_hap positions) read-out is one
precomputed matrix applied to the batch in one batched product per axis (`ActorRegulariser.
readout`, axis-major), and with a `HapPrior` the loss and its gradient w.r.t. the actions are
computed together by hand (L_sim in one compiled pass, `distgprl.agents.similarity`) and
attached to autograd as a single node (`ActorRegulariser._fused`). Values and gradients are
tested against a per-window autograd reference implementation to 1e-9 in float64
(tests/agents/test_regularisers.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, cast

import numpy as np
import torch
from torch import nn

from distgprl.adaptation.layout import ActionLayout, AuxLayout
from distgprl.agents.similarity import similarity_with_gradient
from distgprl.config_types import SACConfig
from distgprl.safety.hap_filter import MovingObstacleFilter
from distgprl.safety.hap_loss import ValueWithGradient
from distgprl.skill.gp import GPSkill

ACCELERATION_REFERENCE_FLOOR = 1e-3
"""Smallest demonstration mean L1 acceleration (m/s^2) the L1 term is divided by."""


class HapLoss(Protocol):
    """What `ActorRegulariser` needs of its HAP prior: L_hap of query positions (B, N_q, 3),
    m, differentiable w.r.t. them (`distgprl.safety.hap_loss.HapPrior.loss`, or any module
    with such a ``loss``)."""

    def loss(
        self,
        x: torch.Tensor,
        anchors: torch.Tensor | np.ndarray | None = None,
        moving: MovingObstacleFilter | None = None,
    ) -> torch.Tensor: ...


class FusedHapLoss(HapLoss, Protocol):
    """A `HapLoss` that also gives its values and gradient without autograd
    (`HapPrior.values_and_gradient`): the regulariser then computes its gradient by hand."""

    def values_and_gradient(
        self,
        x: np.ndarray,
        anchors: np.ndarray | None = None,
        moving: MovingObstacleFilter | None = None,
    ) -> tuple[np.ndarray, np.ndarray]: ...


@dataclass(frozen=True)
class RegulariserWeights:
    """lambda_sim, lambda_hap (Eq. actor_final_compact) and lambda_v, lambda_a (Eq. sim_compact).

    lambda_a weighs the *relative* L1 acceleration error: `ActorRegulariser` divides the L1 term
    by the demonstration's own mean L1 acceleration (``acceleration_reference``), so that both
    terms of Eq. sim_compact are dimensionless like 1 - cos (DESIGN §3). The
    defaults are `distgprl.config_types.SACConfig`'s.
    """

    lambda_sim: float = SACConfig.lambda_sim
    lambda_hap: float = SACConfig.lambda_hap
    lambda_velocity: float = SACConfig.lambda_velocity
    lambda_acceleration: float = SACConfig.lambda_acceleration


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

    # buffers (`register_buffer`), see __init__ and `_build_flat_maps`
    indices: torch.Tensor
    operators: torch.Tensor
    scale: torch.Tensor
    mask: torch.Tensor
    prior_mean: torch.Tensor
    velocity_map: torch.Tensor
    acceleration_map: torch.Tensor
    demo_velocity: torch.Tensor
    demo_acceleration: torch.Tensor
    hap_map: torch.Tensor
    anchor_map: torch.Tensor
    readout_map: torch.Tensor
    readout_bias: torch.Tensor
    demo_direction: torch.Tensor

    def __init__(
        self,
        skill: GPSkill,
        layout: ActionLayout,
        weights: RegulariserWeights,
        hap_prior: HapLoss | None = None,
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

        def buffer(name: str, value: np.ndarray, dtype: torch.dtype = torch.float32) -> None:
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
        # Eq. sim_compact's L1 term in units of the demonstration's own acceleration:
        # (1/T) sum_t |zeta''(t)|_1 (m/s^2 and rad/s^2 over the six axes), floored so that a
        # demonstration at rest cannot blow the weight up.
        self.acceleration_reference = max(
            float(np.abs(skill.acceleration_map(tau) @ demo_centered).sum(axis=1).mean()),
            ACCELERATION_REFERENCE_FLOOR,
        )
        self.acceleration_weight = weights.lambda_acceleration / self.acceleration_reference
        hap_tau = np.linspace(0.0, 1.0, n_hap_queries)
        buffer("hap_map", skill.position_map(hap_tau))
        self.moving_filter = moving_filter if self.hap_prior is not None else None
        # Where Gamma, the step one-hot and the anchors sit in the env's aux observation.
        self.split_gradients: dict[str, torch.Tensor] | None = None  # see `term_gradients`
        self.aux_layout = AuxLayout(self.n_via_points, self.n_steps, self.moving_filter is not None)
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
        """Every read-out of the adapted trajectory as one matrix over the via-point axis.

        The adapted centered via-points of a sample at step s are c + D_s (scale * a) per
        axis (Eqs. transformed/updated), c = Gamma - mu (N, 6), a the raw action (A_v, 6),
        D_s (N, A_v) = scatter onto the window of mask * S_W. Velocities V, accelerations A
        and the L_hap positions H are linear in them, so with M = [V; A; H] (T + T + N_q, N)

            out[b, j] = [M, M D_0,j, ..., M D_{S-1},j]
                        [c[b, :, j]; onehot(s_b) (x) scale_j a[b, :, j]]

        for each axis j (D_s,j from axis j's S_W): one batched
        (6, B, N + S*A_v) x (6, N + S*A_v, 2T + N_q) product for the batch (axis-major).
        Products are taken in float64 from the module's own (float32) buffers, so they are
        exact images of the maps that the per-window code applies.
        """
        f64 = torch.float64
        n, steps, per_step = self.n_via_points, self.n_steps, self.points_per_step
        maps = torch.cat(
            [self.velocity_map.to(f64), self.acceleration_map.to(f64), self.hap_map.to(f64)]
        )  # (2T + N_q, N)
        self._n_similarity = self.velocity_map.shape[0]
        selection = torch.zeros(steps, per_step, n, dtype=f64)  # window row p -> via-point
        selection.scatter_(2, self.indices.unsqueeze(-1), 1.0)
        # D_s,j[v, p'] = sum_p [indices[s, p] = v] mask[s, p] S_W,j[s, p, p'] (S, 6, N, A_v):
        # one S_W per axis j
        scatter = torch.einsum(
            "spv,sp,sapq->savq", selection, self.mask.to(f64), self.operators.to(f64)
        )
        readout = torch.stack(
            [
                torch.cat([maps, *(maps @ scatter[s, j] for s in range(steps))], dim=1)
                for j in range(6)
            ]
        )  # (6, 2T + N_q, N + S A_v)
        t = self._n_similarity
        bias = torch.zeros(6, readout.shape[1], dtype=f64)  # per axis j
        bias[:, t : 2 * t] = -self.demo_acceleration.to(f64).T
        bias[:3, 2 * t :] = self.prior_mean.to(f64)[:3, None]
        demo_velocity = self.demo_velocity.to(f64)
        direction = demo_velocity / demo_velocity.norm(dim=-1, keepdim=True).clamp_min(1e-8)
        self.register_buffer("readout_map", readout.transpose(1, 2).contiguous(), persistent=False)
        self.register_buffer("readout_bias", bias, persistent=False)
        self.register_buffer("demo_direction", direction.T.contiguous(), persistent=False)
        self._cast: dict[tuple, tuple[torch.Tensor, ...]] = {}

    def _flat(self, like: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """readout_map, readout_bias, demo_direction, scale, prior_mean as ``like`` (cached),
        and the action rows of the read-out map transposed, (6, 2T + N_q, S A_v)."""
        key = (like.dtype, like.device, self.readout_map.device, self.readout_map.data_ptr())
        cached = self._cast.get(key)
        if cached is None:
            cached = tuple(
                t.to(device=like.device, dtype=like.dtype)
                for t in (
                    self.readout_map,
                    self.readout_bias,
                    self.demo_direction,
                    self.scale,
                    self.prior_mean,
                )
            )
            actions_map = cached[0][:, self.n_via_points :].transpose(1, 2).contiguous()
            cached = (*cached, actions_map)
            self._cast = {key: cached}
        return cached

    def readout(self, aux: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Velocities, accelerations minus the demo's, positions of the adapted trajectory.

        One batched matrix product (see `_build_flat_maps`). Shape (6, B, 2T + N_q),
        axis-major: ``[:, :, :T]`` velocities (m/s or rad/s: the skill's maps are per
        second), ``[:, :, T:2T]`` accelerations minus the demonstration's, ``[:3, :, 2T:]``
        positions, m (rows 3-5 of that block are the orientation components, unused).
        """
        batch = aux.shape[0]
        n, steps = self.n_via_points, self.n_steps
        readout_map, bias, _, scale, prior_mean, _ = self._flat(actions)
        centered = aux[:, self.aux_layout.gamma].reshape(batch, n, 6).to(actions.dtype)
        centered = centered - prior_mean
        step = aux[:, self.aux_layout.step].argmax(dim=1)
        one_hot = (step.unsqueeze(1) == torch.arange(steps, device=step.device)).to(actions.dtype)
        raw = actions.reshape(batch, self.points_per_step, 6) * scale
        selected = one_hot[:, :, None, None] * raw.unsqueeze(1)  # (B, S, A_v, 6)
        stacked = torch.cat([centered, selected.reshape(batch, -1, 6)], 1)  # (B, N + S A_v, 6)
        columns = stacked.permute(2, 0, 1).contiguous()  # (6, B, N + S A_v)
        return torch.bmm(columns, readout_map).add_(bias.unsqueeze(1))

    def adapted_via_points(self, aux: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Gamma + Delta Gamma for a batch, shape (B, N, 6) (Eqs. transformed/updated)."""
        batch = aux.shape[0]
        n = self.n_via_points
        gamma = aux[:, self.aux_layout.gamma].reshape(batch, n, 6)
        step = aux[:, self.aux_layout.step].argmax(dim=1)
        raw = actions.reshape(batch, self.points_per_step, 6) * self.scale
        # per sample b and axis a: S_W,a of the sample's step times the axis's column
        delta = torch.einsum("baij,bja->bia", self.operators[step], raw)
        delta = delta * self.mask[step].unsqueeze(-1)
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
            self.acceleration_weight * l1.mean(dim=1)
        )

    def _similarity_from_readout(self, out: torch.Tensor) -> torch.Tensor:
        """Batch mean of L_sim (Eq. sim_compact) from `readout`'s output, a scalar."""
        batch, t = out.shape[1], self._n_similarity
        direction = self._flat(out)[2].unsqueeze(1)  # (6, 1, T)
        velocity = out[:, :, :t]  # (6, B, T)
        # cos = v . d / (|v| |d|), d/|d| precomputed (torch's cosine_similarity clamps the
        # norms at 1e-8 likewise).
        cos = (velocity * direction).sum(0) / velocity.square().sum(0).sqrt().clamp_min(1e-8)
        l1 = out[:, :, t : 2 * t].abs().sum()  # sum over the 6 axes, B and T
        samples = t * batch
        return self.weights.lambda_velocity * (1.0 - cos.sum() / samples) + (
            self.acceleration_weight * l1 / samples
        )

    def _anchors(self, aux: torch.Tensor) -> torch.Tensor:
        """The moving obstacles' anchors at the L_hap query times, (B, N_q, 3), m, from aux."""
        n = self.n_via_points
        if aux.shape[1] != self.aux_layout.size:
            raise ValueError(
                f"aux has {aux.shape[1]} entries; the moving-obstacle filter needs "
                f"{self.aux_layout.size} (Gamma, step one-hot, anchors)"
            )
        anchor = aux[:, self.aux_layout.anchor].reshape(-1, n, 3)
        return torch.matmul(self.anchor_map.to(aux.dtype), anchor)

    def forward(self, aux: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, dict]:
        """Total regularisation (scalar) and its logged terms; the gradient reaches ``actions``.

        With a `HapPrior` (or no prior) the loss and its gradient w.r.t. the actions are
        computed together without autograd (`_fused`); any other prior module (with a
        differentiable ``loss(x)``) goes through autograd. ``aux`` gets no gradient either way.
        """
        terms: dict[str, float] = {}
        if self.weights.lambda_sim <= 0 and self.hap_prior is None:
            return actions.new_zeros(()), terms
        if self.hap_prior is None or hasattr(self.hap_prior, "values_and_gradient"):
            return ValueWithGradient.apply(actions, lambda: self._fused(aux, actions, terms)), terms
        total = actions.new_zeros(())
        out = self.readout(aux, actions)
        if self.weights.lambda_sim > 0:
            l_sim = self._similarity_from_readout(out)
            total = total + self.weights.lambda_sim * l_sim
            terms["l_sim"] = float(l_sim.detach())
        positions = out[:3, :, 2 * self._n_similarity :].permute(1, 2, 0)  # (B, N_q, 3)
        if self.moving_filter is None:
            l_hap = self.hap_prior.loss(positions)
        else:
            l_hap = self.hap_prior.loss(positions, self._anchors(aux), self.moving_filter)
        total = total + self.weights.lambda_hap * l_hap
        terms["l_hap"] = float(l_hap.detach())
        return total, terms

    def _numpy_maps(self, dtype: np.dtype) -> dict[str, np.ndarray]:
        """The read-out's pieces as NumPy arrays of ``dtype`` (cached): ``centered`` (6, N, Q)
        and, per step s, ``actions`` [s] (6, A_v, Q) and its transpose ``actions_t`` [s]
        (6, Q, A_v) (the rows of `readout_map`), ``bias`` (6, 1, Q), ``direction`` (6, T),
        ``scale`` (6,), ``prior_mean`` (6,) and ``anchor_map`` (N_q, N)."""
        key = (np.dtype(dtype).str, self.readout_map.data_ptr())
        cached = self.__dict__.get("_numpy_cache")
        if cached is not None and cached[0] == key:
            return cached[1]
        n, per_step = self.n_via_points, self.points_per_step

        def numpy(tensor: torch.Tensor) -> np.ndarray:
            return np.ascontiguousarray(tensor.detach().cpu().numpy().astype(dtype))

        readout_map = numpy(self.readout_map)  # (6, N + S A_v, Q)
        blocks = [
            readout_map[:, n + s * per_step : n + (s + 1) * per_step] for s in range(self.n_steps)
        ]
        maps = {
            "centered": np.ascontiguousarray(readout_map[:, :n]),
            "actions": np.stack([np.ascontiguousarray(b) for b in blocks]),
            "actions_t": np.stack([np.ascontiguousarray(b.transpose(0, 2, 1)) for b in blocks]),
            "bias": numpy(self.readout_bias)[:, None, :],
            "direction": numpy(self.demo_direction),
            "scale": numpy(self.scale),
            "prior_mean": numpy(self.prior_mean),
            "anchor_map": numpy(self.anchor_map),
        }
        self.__dict__["_numpy_cache"] = (key, maps)
        return maps

    def _workspace(self, name: str, shape: tuple[int, ...], dtype: np.dtype) -> np.ndarray:
        """A buffer of ``shape`` and ``dtype`` kept between updates (uninitialised): the
        read-out and its gradient are consumed within `_fused`, so reusing them saves
        allocating and faulting in ~0.7 MB each per update (batch 256)."""
        buffers: dict[str, np.ndarray] = self.__dict__.setdefault("_workspaces", {})
        buffer = buffers.get(name)
        if buffer is None or buffer.shape != shape or buffer.dtype != dtype:
            buffer = buffers[name] = np.empty(shape, dtype=dtype)
        return buffer

    def _numpy_readout(
        self, aux: np.ndarray, actions: np.ndarray
    ) -> tuple[np.ndarray, list[slice]]:
        """`readout` in NumPy (issue 49), (6, B, 2T + N_q), of samples sorted by step (the
        caller sorts ``aux`` and ``actions``), and each step's slice of samples.

        The action columns of a sample are those of its own step only, so instead of one
        product over all S step blocks (zeros but one) each step's samples are multiplied by
        their block: half the products and no scattered copy of the actions.
        """
        batch, n = aux.shape[0], self.n_via_points
        maps = self._numpy_maps(actions.dtype)
        centered = aux[:, self.aux_layout.gamma].reshape(batch, n, 6) - maps["prior_mean"]
        # (6, B, N) contiguous: NumPy's batched matmul reaches BLAS only for contiguous rows
        out = self._workspace("readout", (6, batch, maps["centered"].shape[2]), actions.dtype)
        np.matmul(np.ascontiguousarray(centered.transpose(2, 0, 1)), maps["centered"], out=out)
        out += maps["bias"]
        raw = np.ascontiguousarray(
            (actions.reshape(batch, self.points_per_step, 6) * maps["scale"]).transpose(2, 0, 1)
        )
        counts = np.bincount(aux[:, self.aux_layout.step].argmax(axis=1), minlength=self.n_steps)
        bounds = np.concatenate([[0], np.cumsum(counts)])
        groups = [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
        for s, rows in enumerate(groups):
            if rows.stop > rows.start:
                out[:, rows] += np.matmul(raw[:, rows], maps["actions"][s])
        return out, groups

    def _fused(
        self, aux: torch.Tensor, actions: torch.Tensor, terms: dict[str, float]
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Total (scalar) and d total / d actions (B, A), no autograd; fills ``terms``.

        Gradients by hand through the read-out (linear; `_numpy_readout`): d out for L_sim
        (Eq. sim_compact, one compiled pass: `distgprl.agents.similarity.
        similarity_with_gradient`) and for L_hap (the soft-min's own gradient,
        `HapPrior.values_and_gradient`), then d actions = d out @ (the sample's step block of
        the map)^T times the scale (`_numpy_to_actions`). All in NumPy (issue 49: the torch
        version's small ops cost more than their arithmetic).
        """
        batch, t = actions.shape[0], self._n_similarity
        aux_np = aux.detach().cpu().numpy()
        # samples sorted by step (stable): each step's samples are one slice
        order = np.argsort(aux_np[:, self.aux_layout.step].argmax(axis=1), kind="stable")
        aux_np = aux_np[order]
        out, groups = self._numpy_readout(aux_np, actions.detach().cpu().numpy()[order])
        maps = self._numpy_maps(out.dtype)
        gradient = self._workspace("gradient", out.shape, out.dtype)
        gradient[3:, :, 2 * t :] = 0.0  # orientation rows of the L_hap block: unused
        total = 0.0
        weights = self.weights
        if weights.lambda_sim > 0:
            l_sim = similarity_with_gradient(
                out, maps["direction"], t, weights.lambda_velocity,
                self.acceleration_weight, weights.lambda_sim, gradient,
            )  # fmt: skip
            total += weights.lambda_sim * l_sim
            terms["l_sim"] = l_sim
        else:
            gradient[:, :, : 2 * t] = 0.0
        if self.hap_prior is not None:
            positions = out[:3, :, 2 * t :].transpose(1, 2, 0).reshape(-1, 3)  # (B N_q, 3)
            anchors = None
            if self.moving_filter is not None:
                anchors = self._numpy_anchors(aux_np, maps["anchor_map"])
            # `loss` comes here only for a prior with `values_and_gradient`
            values, jacobian = cast(FusedHapLoss, self.hap_prior).values_and_gradient(
                positions, anchors, self.moving_filter
            )
            l_hap = float(values.mean(dtype=np.float64))
            total += weights.lambda_hap * l_hap
            terms["l_hap"] = l_hap
            gradient[:3, :, 2 * t :] = jacobian.reshape(batch, -1, 3).transpose(2, 0, 1) * (
                weights.lambda_hap / len(values)
            )
            if self.split_gradients is not None:  # `term_gradients` only (never in training)
                threshold = getattr(self.hap_prior, "outside_threshold", None)
                if threshold is not None:
                    outside = (values.reshape(batch, -1) > threshold).any(axis=1)
                    self.split_gradients["hap_outside"] = torch.from_numpy(outside)
        else:
            gradient[:3, :, 2 * t :] = 0.0
        if self.split_gradients is not None:  # `term_gradients`: each term's own gradient
            for name, first, stop in (("l_sim", 0, 2 * t), ("l_hap", 2 * t, out.shape[2])):
                split = self._numpy_to_actions(gradient, groups, order, first, stop)
                self.split_gradients[name] = torch.from_numpy(split).to(actions.device)
        total_tensor = torch.tensor(total, dtype=actions.dtype, device=actions.device)
        grad_actions = self._numpy_to_actions(gradient, groups, order, 0, out.shape[2])
        return total_tensor, torch.from_numpy(grad_actions).to(actions.device)

    def _numpy_anchors(self, aux: np.ndarray, anchor_map: np.ndarray) -> np.ndarray:
        """`_anchors` in NumPy: the anchors at the L_hap query times (B, N_q, 3), m, as one
        (N_q, N) x (N, 3B) product."""
        n = self.n_via_points
        if aux.shape[1] != self.aux_layout.size:
            self._anchors(torch.from_numpy(aux))  # raises the size error
        batch = aux.shape[0]
        anchor = aux[:, self.aux_layout.anchor].reshape(batch, n, 3).astype(anchor_map.dtype)
        at_queries = anchor_map @ anchor.transpose(1, 0, 2).reshape(n, 3 * batch)
        return np.ascontiguousarray(at_queries.reshape(-1, batch, 3).transpose(1, 0, 2))

    def _numpy_to_actions(
        self,
        grad_out: np.ndarray,
        groups: list[slice],
        order: np.ndarray,
        first: int,
        stop: int,
    ) -> np.ndarray:
        """d loss / d actions (B, A), in the batch's order, from d loss / d read-out
        (6, B, Q) of the samples sorted by step (``order``: the sorted samples' indices) over
        the columns ``first:stop``: each step's samples times the transpose of their block,
        times the scale."""
        batch = grad_out.shape[1]
        maps = self._numpy_maps(grad_out.dtype)
        grad_raw = np.empty((6, batch, self.points_per_step), dtype=grad_out.dtype)
        for s, rows in enumerate(groups):
            if rows.stop > rows.start:
                np.matmul(
                    grad_out[:, rows, first:stop],
                    maps["actions_t"][s][:, first:stop],
                    out=grad_raw[:, rows],
                )
        grad_raw *= maps["scale"][:, None, None]
        grad_actions = np.empty((batch, grad_raw.shape[2] * 6), dtype=grad_out.dtype)
        grad_actions[order] = grad_raw.transpose(1, 2, 0).reshape(batch, -1)
        return grad_actions

    def term_gradients(self, aux: torch.Tensor, actions: torch.Tensor) -> dict[str, torch.Tensor]:
        """Each weighted term's gradient w.r.t. the actions, ``{"l_sim": (B, A), "l_hap": (B,
        A)}`` (terms the method does not use are zero): d (lambda_sim L_sim) / d a and d
        (lambda_hap L_hap) / d a of the batch-mean losses (Eq. actor_final_compact's
        regularisers), no autograd. Only for the fused path (a `HapPrior` or no prior)."""
        if self.hap_prior is not None and not hasattr(self.hap_prior, "values_and_gradient"):
            raise ValueError("term_gradients needs the fused path (a HapPrior or no prior)")
        self.split_gradients = {}
        try:
            with torch.no_grad():
                self._fused(aux, actions, {})
            return self.split_gradients
        finally:
            self.split_gradients = None
