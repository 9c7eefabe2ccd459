"""The SAC update of environment v5 (`RegularisedSAC.train` before issue 49), kept verbatim
as the reference that `tests/agents/test_update.py` checks the new update against: one update
from the same model, replay buffer and random streams, to float tolerance."""

from __future__ import annotations

import numpy as np
import torch as th
from stable_baselines3.common.utils import polyak_update
from torch.nn import functional as F

__all__ = ["reference_train"]


def reference_train(self, gradient_steps: int, batch_size: int = 64) -> None:
    """`RegularisedSAC.train` before issue 49 (environment v5), verbatim; ``self`` a
    `RegularisedSAC`."""
    # Copied from stable_baselines3 2.9.2 SAC.train; changes marked "distgprl:".
    self.policy.set_training_mode(True)
    optimizers = [self.actor.optimizer, self.critic.optimizer]
    if self.ent_coef_optimizer is not None:
        optimizers += [self.ent_coef_optimizer]
    self._update_learning_rate(optimizers)

    # distgprl: GPRL's annealed exploration sets the fixed coefficient each update.
    if self.entropy_schedule is not None:
        self.ent_coef_tensor = th.tensor(self.current_entropy_coefficient(), device=self.device)

    ent_coef_losses, ent_coefs = [], []
    actor_losses, critic_losses = [], []
    regulariser_logs: dict[str, list[float]] = {}

    for gradient_step in range(gradient_steps):
        replay_data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
        discounts = replay_data.discounts if replay_data.discounts is not None else self.gamma

        if self.use_sde:
            self.actor.reset_noise()

        actions_pi, log_prob = self.actor.action_log_prob(replay_data.observations)
        log_prob = log_prob.reshape(-1, 1)

        ent_coef_loss = None
        if self.ent_coef_optimizer is not None and self.log_ent_coef is not None:
            ent_coef = th.exp(self.log_ent_coef.detach())
            assert isinstance(self.target_entropy, float)
            ent_coef_loss = -(self.log_ent_coef * (log_prob + self.target_entropy).detach()).mean()
            ent_coef_losses.append(ent_coef_loss.item())
        else:
            ent_coef = self.ent_coef_tensor

        ent_coefs.append(ent_coef.item())

        if ent_coef_loss is not None and self.ent_coef_optimizer is not None:
            self.ent_coef_optimizer.zero_grad()
            ent_coef_loss.backward()
            self.ent_coef_optimizer.step()

        with th.no_grad():
            next_actions, next_log_prob = self.actor.action_log_prob(replay_data.next_observations)
            next_q_values = th.cat(
                self.critic_target(replay_data.next_observations, next_actions), dim=1
            )
            next_q_values, _ = th.min(next_q_values, dim=1, keepdim=True)
            next_q_values = next_q_values - ent_coef * next_log_prob.reshape(-1, 1)
            target_q_values = (
                replay_data.rewards + (1 - replay_data.dones) * discounts * next_q_values
            )

        current_q_values = self.critic(replay_data.observations, replay_data.actions)
        critic_loss = 0.5 * sum(
            F.mse_loss(current_q, target_q_values) for current_q in current_q_values
        )
        assert isinstance(critic_loss, th.Tensor)
        critic_losses.append(critic_loss.item())

        self.critic.optimizer.zero_grad()
        critic_loss.backward()
        self.critic.optimizer.step()

        # distgprl: the actor loss needs dQ/da only; with the critic's parameters frozen
        # its backward skips their weight gradients (which the next critic update zeroes
        # anyway), so the update is numerically unchanged and cheaper.
        self.critic.requires_grad_(False)
        q_values_pi = th.cat(self.critic(replay_data.observations, actions_pi), dim=1)
        self.critic.requires_grad_(True)
        min_qf_pi, _ = th.min(q_values_pi, dim=1, keepdim=True)
        actor_loss = (ent_coef * log_prob - min_qf_pi).mean()
        actor_losses.append(actor_loss.item())

        # distgprl: + lambda_sim L_sim + lambda_hap L_hap (Eq. actor_final_compact),
        # from the actor's sampled actions so the gradients reach the actor.
        if self.regulariser is not None:
            regularisation, terms = self.regulariser(replay_data.observations["aux"], actions_pi)
            actor_loss = actor_loss + regularisation
            for key, value in terms.items():
                regulariser_logs.setdefault(key, []).append(value)

        self.actor.optimizer.zero_grad()
        actor_loss.backward()
        self.actor.optimizer.step()

        if gradient_step % self.target_update_interval == 0:
            polyak_update(self.critic.parameters(), self.critic_target.parameters(), self.tau)
            polyak_update(self.batch_norm_stats, self.batch_norm_stats_target, 1.0)

    self._n_updates += gradient_steps

    self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
    self.logger.record("train/ent_coef", np.mean(ent_coefs))
    self.logger.record("train/actor_loss", np.mean(actor_losses))
    self.logger.record("train/critic_loss", np.mean(critic_losses))
    if len(ent_coef_losses) > 0:
        self.logger.record("train/ent_coef_loss", np.mean(ent_coef_losses))
    # distgprl: log each regulariser term.
    self.last_regulariser_terms = {k: float(np.mean(v)) for k, v in regulariser_logs.items()}
    for key, value in self.last_regulariser_terms.items():
        self.logger.record(f"train/{key}", value)
    self.last_regulariser_terms.update(
        actor_loss=float(np.mean(actor_losses)),
        critic_loss=float(np.mean(critic_losses)),
        ent_coef=float(np.mean(ent_coefs)),
    )
