"""SAC with the regularised actor loss of Dist-GPRL (Eq. actor_final_compact).

`RegularisedSAC.train` is a minimal copy of ``stable_baselines3.sac.SAC.train`` as of
stable-baselines3 **2.9.2** (pinned in pyproject.toml / constraints.txt). The changes of
what it computes, each marked ``# distgprl:``, are

1. the actor loss adds ``regulariser(aux, actions_pi)`` — lambda_sim L_sim +
   lambda_hap L_hap computed from the actor's sampled actions — and logs its terms;
2. an optional entropy-coefficient schedule (GPRL's annealed exploration) replaces the
   fixed coefficient when SAC's automatic tuning is off.

The other ``# distgprl:`` marks are speed work on the same random draws, equal to SB3's to
float rounding (the replay batch gathered into preallocated tensors, the actor's action and
log-probability without a ``torch.distributions`` object, the critic frozen in the actor
loss's backward, the target update as one foreach lerp: `distgprl.agents.update`).

Networks see only the ``state`` key of the Dict observation (`StateOnlyExtractor`); the
``aux`` key (current via-points, step one-hot and, with the HAP prior, the moving obstacles'
anchors; `distgprl.adaptation.layout.AuxLayout`) feeds the regulariser.

Outside the copy, `RegularisedSAC._setup_learn` gives a silent model (``verbose=0``, no
tensorboard) an in-memory logger: SB3's default makes an empty ``SB3-<time>`` folder in the
temporary directory at every ``learn`` call (every run, resume and test).
`training_logger` is the logger a run gives its model instead: the same records, also
written as TensorBoard event files when the optional ``tensorboard`` package is installed;
`EpisodeLogCallback` adds each training episode's return, success and collision to it.
Neither touches a random stream, so training stays bit-identical with or without them.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3 import SAC
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger, TensorBoardOutputFormat
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.utils import polyak_update
from stable_baselines3.sac.policies import MultiInputPolicy
from torch.nn import functional as F

from distgprl.agents.update import ReplaySampler, polyak_lerp, squashed_gaussian_sample

SB3_VERSION_COPIED = "2.9.2"

__all__ = [
    "EpisodeLogCallback",
    "RegularisedSAC",
    "RegularisedSACPolicy",
    "StateOnlyExtractor",
    "exponential_anneal",
    "tensorboard_available",
    "training_logger",
]


_TENSORBOARD_NOTE_SHOWN = False


def tensorboard_available() -> bool:
    """Whether the optional ``tensorboard`` package (``distgprl[tensorboard]``) is installed."""
    try:
        from torch.utils.tensorboard import SummaryWriter  # noqa: F401
    except ImportError:
        return False
    return True


@contextmanager
def _interrupts_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM (main thread, where a Python handler is installed) until the
    block ends, then deliver them to that handler.

    TensorBoard's writer hands records to its thread through a `queue.Queue`; a
    KeyboardInterrupt raised between the queue's append and its task count leaves the count
    one short, and the writer thread dies with ``task_done() called too many times`` — a
    traceback on every such Ctrl-C. Deferred, the interrupt lands between two writes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    handlers = {
        number: signal.getsignal(number)
        for number in (signal.SIGINT, signal.SIGTERM)
        if callable(signal.getsignal(number))
    }
    for number in handlers:
        signal.signal(number, lambda received, _frame: pending.append(received))
    try:
        yield
    finally:
        for number, handler in handlers.items():
            signal.signal(number, handler)
        for received in pending:
            cast(Callable[[int, Any], Any], handlers[signal.Signals(received)])(received, None)


class _ResumableTensorBoard(TensorBoardOutputFormat):
    """SB3's TensorBoard writer with a ``purge_step``: on a resume from step k, TensorBoard
    discards the earlier event files' records at steps > k (written after the checkpoint by
    the killed process), so the resumed curves do not overlap. A signal arriving while it
    writes is delivered when the write is done (`_interrupts_deferred`)."""

    def __init__(self, folder: str, purge_step: int | None) -> None:
        from torch.utils.tensorboard import SummaryWriter

        self.writer = SummaryWriter(log_dir=folder, purge_step=purge_step)
        self._is_closed = False

    def write(
        self,
        key_values: dict[str, Any],
        key_excluded: dict[str, tuple[str, ...]],
        step: int = 0,
    ) -> None:
        with _interrupts_deferred():
            super().write(key_values, key_excluded, step)

    def close(self) -> None:
        with _interrupts_deferred():
            super().close()


def training_logger(tb_dir: Path | None, start_step: int = 0) -> Logger:
    """The logger of one training run (set it with ``model.set_logger``).

    Args:
        tb_dir: folder for TensorBoard event files (created); None, or ``tensorboard`` not
            installed: records are kept in memory only (the latter said once per process on
            stderr).
        start_step: the run's current step (environment steps); > 0 on a resume, where
            records of the interrupted process after this step are purged.
    """
    global _TENSORBOARD_NOTE_SHOWN
    if tb_dir is None:
        return Logger(folder=None, output_formats=[])
    if not tensorboard_available():
        if not _TENSORBOARD_NOTE_SHOWN:
            print(
                "note: tensorboard is not installed (pip install 'distgprl[tensorboard]'); "
                "no TensorBoard event file is written",
                file=sys.stderr,
            )
            _TENSORBOARD_NOTE_SHOWN = True
        return Logger(folder=None, output_formats=[])
    tb_dir.mkdir(parents=True, exist_ok=True)
    # Records at steps <= start_step were all written before the checkpoint (its last
    # episode ends at start_step): purge only what came after.
    writer = _ResumableTensorBoard(str(tb_dir), start_step + 1 if start_step > 0 else None)
    return Logger(folder=str(tb_dir), output_formats=[writer])


class EpisodeLogCallback(BaseCallback):
    """Records each finished training episode into the model's logger and dumps it at the
    episode's last step: ``rollout/episode_return`` (sum of the rewards: r_tc, and where the
    method has them r_sd, lambda_ga r_ga and GPRL's r_signature), ``rollout/episode_length``
    (steps: windows, or ProMP-RRL's 0.1 s RL steps), ``rollout/episode_success`` and
    ``rollout/episode_collision`` (0/1, from the final step's ``info``). The dump also
    writes the latest ``train/*`` records (losses, alpha, regulariser terms)."""

    def __init__(self) -> None:
        super().__init__(verbose=0)
        self._returns: np.ndarray | None = None
        self._lengths: np.ndarray | None = None

    def _on_step(self) -> bool:
        rewards = np.asarray(self.locals["rewards"], dtype=np.float64)
        if self._returns is None or self._lengths is None:
            self._returns = np.zeros_like(rewards)
            self._lengths = np.zeros(rewards.shape, dtype=np.int64)
        returns, lengths = self._returns, self._lengths
        returns += rewards
        lengths += 1
        for index, done in enumerate(np.asarray(self.locals["dones"])):
            if not done:
                continue
            info = self.locals["infos"][index]
            self.logger.record("rollout/episode_return", float(returns[index]))
            self.logger.record("rollout/episode_length", int(lengths[index]))
            for key in ("success", "collision"):
                if key in info:
                    self.logger.record(f"rollout/episode_{key}", float(info[key]))
            self.logger.dump(step=self.num_timesteps)
            returns[index] = 0.0
            lengths[index] = 0
        return True


class StateOnlyExtractor(BaseFeaturesExtractor):
    """Features = the ``state`` entry of a Dict observation (``aux`` is ignored)."""

    def __init__(self, observation_space: gym.spaces.Dict) -> None:
        state_shape = observation_space["state"].shape
        assert state_shape is not None  # a Box
        super().__init__(observation_space, features_dim=int(state_shape[0]))

    def forward(self, observations: dict[str, th.Tensor]) -> th.Tensor:
        return observations["state"]


def exponential_anneal(start: float, end: float) -> Callable[[float], float]:
    """Entropy coefficient decaying exponentially from ``start`` to ``end``.

    The argument is the training progress in [0, 1] (0 at the first step):
    alpha(p) = start * (end / start) ** p.
    """
    if start <= 0 or end <= 0:
        raise ValueError("anneal start and end must be positive")

    def schedule(progress: float) -> float:
        return float(start * (end / start) ** min(max(progress, 0.0), 1.0))

    return schedule


class RegularisedSACPolicy(MultiInputPolicy):
    """SB3's ``MultiInputPolicy`` whose training flag is set on a cached module list (issue
    49): SB3's recursive ``train(mode)`` costs ~0.25 ms, twice per training step (the update
    and the rollout), this ~0.01 ms; the same flags end up set."""

    def set_training_mode(self, mode: bool) -> None:
        modules = self.__dict__.get("_training_modules")
        if modules is None:
            # SB3's SACPolicy.set_training_mode: the actor, the critic and the policy itself
            # (the target critic stays in evaluation mode)
            modules = [self, *self.actor.modules(), *self.critic.modules()]
            self.__dict__["_training_modules"] = modules
        for module in modules:  # nn.Module keeps ``training`` in its __dict__ (no hooks)
            module.__dict__["training"] = mode


@dataclass
class _UpdateLogs:
    """The per-gradient-step values one `RegularisedSAC.train` call averages into its logs."""

    ent_coef_losses: list[float] = field(default_factory=list)
    ent_coefs: list[float] = field(default_factory=list)
    actor_losses: list[float] = field(default_factory=list)
    critic_losses: list[float] = field(default_factory=list)
    regulariser: dict[str, list[float]] = field(default_factory=dict)


class RegularisedSAC(SAC):
    """SB3 SAC whose actor loss adds the Dist-GPRL regularisers.

    Args:
        regulariser: a module ``(aux, actions) -> (scalar loss, dict of floats)`` or None.
        entropy_schedule: ``progress -> alpha`` used instead of a fixed ``ent_coef``
            (requires a numeric ``ent_coef``), or None.
        total_training_steps: steps over which the schedule's progress runs 0 -> 1.

    All other arguments go to `stable_baselines3.SAC`.
    """

    policy_aliases = {**SAC.policy_aliases, "MultiInputPolicy": RegularisedSACPolicy}

    freeze_critic_in_actor_loss = True
    """Freeze the critic's parameters in the actor loss's backward (False: SB3's original,
    which computes their unused weight gradients; the tests compare the two)."""

    def __init__(
        self,
        *args,
        regulariser: th.nn.Module | None = None,
        entropy_schedule: Callable[[float], float] | None = None,
        total_training_steps: int = 1,
        **kwargs,
    ) -> None:
        self.regulariser = regulariser
        self.entropy_schedule = entropy_schedule
        self.total_training_steps = max(int(total_training_steps), 1)
        super().__init__(*args, **kwargs)
        if entropy_schedule is not None and self.ent_coef_optimizer is not None:
            raise ValueError("an entropy schedule needs a fixed (numeric) ent_coef")
        if self.regulariser is not None:
            self.regulariser.to(self.device)
        self.last_regulariser_terms: dict[str, float] = {}

    def current_entropy_coefficient(self) -> float:
        """The scheduled alpha at the current step (or the fixed / learned one)."""
        if self.entropy_schedule is not None:
            return self.entropy_schedule(self.num_timesteps / self.total_training_steps)
        if self.log_ent_coef is not None:
            return float(th.exp(self.log_ent_coef.detach()))
        return float(self.ent_coef_tensor)

    def _setup_model(self) -> None:
        super()._setup_model()
        # distgprl (issue 49): the entropy coefficient's Adam fused like the networks' (one
        # kernel instead of a dozen ops for its one scalar).
        if self.ent_coef_optimizer is not None:
            assert self.log_ent_coef is not None  # set with the optimizer
            self.ent_coef_optimizer = th.optim.Adam(
                [self.log_ent_coef], lr=self.lr_schedule(1), fused=True
            )

    def _update_parts(self) -> tuple:
        """The update's cached pieces: the replay sampler (or None: SB3's sample) and the
        critic's, the target critic's and the actor's parameter lists (rebuilt if the
        policy or the buffer was replaced, e.g. by a checkpoint load)."""
        parts = getattr(self, "_update_cache", None)
        if parts is None or parts[0][0] is not self.policy or parts[0][1] is not self.replay_buffer:
            sampler = None
            if ReplaySampler.supports(self.replay_buffer, self._vec_normalize_env):
                sampler = ReplaySampler(self.replay_buffer)
            parts = (
                (self.policy, self.replay_buffer),
                sampler,
                list(self.critic.parameters()),
                list(self.critic_target.parameters()),
            )
            self._update_cache = parts
        return parts

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        # Adapted from stable_baselines3 2.9.2 SAC.train; changes marked "distgprl:" (the
        # replay batch gathered into preallocated tensors, the actor's action and
        # log-probability without a torch.distributions object, the critic frozen through a
        # cached parameter list, the target update one foreach lerp). The losses' .item()
        # stays: on the CPU it is no synchronisation. The loop body is split into SB3's own
        # stages (temperature, critic, actor, target), in SB3's order.
        self.policy.set_training_mode(True)
        optimizers = [self.actor.optimizer, self.critic.optimizer]
        if self.ent_coef_optimizer is not None:
            optimizers += [self.ent_coef_optimizer]
        self._update_learning_rate(optimizers)

        # distgprl: GPRL's annealed exploration sets the fixed coefficient each update.
        if self.entropy_schedule is not None:
            self.ent_coef_tensor = th.tensor(self.current_entropy_coefficient(), device=self.device)

        _, sampler, critic_parameters, target_parameters = self._update_parts()
        fast_actor = not self.use_sde
        logs = _UpdateLogs()

        for gradient_step in range(gradient_steps):
            if sampler is not None:  # distgprl: same draws and values as SB3's sample
                replay_data = sampler.sample(batch_size)
            else:
                replay_data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]

            if self.use_sde:
                self.actor.reset_noise()

            actions_pi, log_prob = self._action_log_prob(replay_data.observations, fast_actor)
            log_prob = log_prob.reshape(-1, 1)
            ent_coef = self._temperature_step(log_prob, logs)
            self._critic_step(replay_data, ent_coef, fast_actor, logs)
            self._actor_step(replay_data, actions_pi, log_prob, ent_coef, critic_parameters, logs)

            if gradient_step % self.target_update_interval == 0:
                polyak_lerp(critic_parameters, target_parameters, self.tau)
                if self.batch_norm_stats:
                    polyak_update(self.batch_norm_stats, self.batch_norm_stats_target, 1.0)

        self._n_updates += gradient_steps
        self._record_update_logs(logs)

    def _temperature_step(self, log_prob: th.Tensor, logs: _UpdateLogs) -> th.Tensor:
        """SB3's entropy-coefficient stage: the coefficient for this gradient step and, when
        it is learned, one optimiser step on its loss."""
        ent_coef_loss = None
        if self.ent_coef_optimizer is not None and self.log_ent_coef is not None:
            ent_coef = th.exp(self.log_ent_coef.detach())
            assert isinstance(self.target_entropy, float)
            ent_coef_loss = -(self.log_ent_coef * (log_prob + self.target_entropy).detach()).mean()
            logs.ent_coef_losses.append(ent_coef_loss.item())
        else:
            ent_coef = self.ent_coef_tensor

        logs.ent_coefs.append(ent_coef.item())

        if ent_coef_loss is not None and self.ent_coef_optimizer is not None:
            self.ent_coef_optimizer.zero_grad()
            ent_coef_loss.backward()
            self.ent_coef_optimizer.step()
        return ent_coef

    def _critic_step(
        self, replay_data, ent_coef: th.Tensor, fast_actor: bool, logs: _UpdateLogs
    ) -> None:
        """SB3's critic stage: the soft Bellman target from the target critics and one
        optimiser step on the twin critics' squared error."""
        discounts = replay_data.discounts if replay_data.discounts is not None else self.gamma
        with th.no_grad():
            next_actions, next_log_prob = self._action_log_prob(
                replay_data.next_observations, fast_actor
            )
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
        logs.critic_losses.append(critic_loss.item())

        self.critic.optimizer.zero_grad()
        critic_loss.backward()
        self.critic.optimizer.step()

    def _actor_step(
        self,
        replay_data,
        actions_pi: th.Tensor,
        log_prob: th.Tensor,
        ent_coef: th.Tensor,
        critic_parameters: list[th.nn.Parameter],
        logs: _UpdateLogs,
    ) -> None:
        """SB3's actor stage, plus the paper's regularisers (Eq. actor_final_compact)."""
        # distgprl: the actor loss needs dQ/da only; with the critic's parameters frozen
        # its backward skips their weight gradients (which the next critic update zeroes
        # anyway), so the update is numerically unchanged and cheaper.
        frozen = critic_parameters if self.freeze_critic_in_actor_loss else []
        for parameter in frozen:
            parameter.requires_grad_(False)
        q_values_pi = th.cat(self.critic(replay_data.observations, actions_pi), dim=1)
        for parameter in frozen:
            parameter.requires_grad_(True)
        min_qf_pi, _ = th.min(q_values_pi, dim=1, keepdim=True)
        actor_loss = (ent_coef * log_prob - min_qf_pi).mean()
        logs.actor_losses.append(actor_loss.item())

        # distgprl: + lambda_sim L_sim + lambda_hap L_hap (Eq. actor_final_compact),
        # from the actor's sampled actions so the gradients reach the actor.
        if self.regulariser is not None:
            regularisation, terms = self.regulariser(replay_data.observations["aux"], actions_pi)
            actor_loss = actor_loss + regularisation
            for key, value in terms.items():
                logs.regulariser.setdefault(key, []).append(value)

        self.actor.optimizer.zero_grad()
        actor_loss.backward()
        self.actor.optimizer.step()

    def _record_update_logs(self, logs: _UpdateLogs) -> None:
        """SB3's logger records, and (distgprl) each regulariser term's mean."""
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/ent_coef", np.mean(logs.ent_coefs))
        self.logger.record("train/actor_loss", np.mean(logs.actor_losses))
        self.logger.record("train/critic_loss", np.mean(logs.critic_losses))
        if len(logs.ent_coef_losses) > 0:
            self.logger.record("train/ent_coef_loss", np.mean(logs.ent_coef_losses))
        self.last_regulariser_terms = {k: float(np.mean(v)) for k, v in logs.regulariser.items()}
        for key, value in self.last_regulariser_terms.items():
            self.logger.record(f"train/{key}", value)
        self.last_regulariser_terms.update(
            actor_loss=float(np.mean(logs.actor_losses)),
            critic_loss=float(np.mean(logs.critic_losses)),
            ent_coef=float(np.mean(logs.ent_coefs)),
        )

    def _action_log_prob(self, observations, fast: bool) -> tuple[th.Tensor, th.Tensor]:
        """The actor's sampled action (B, A) and its log-probability (B,): SB3's
        ``actor.action_log_prob``, or (``fast``, no gSDE) `squashed_gaussian_sample` on the
        actor's mean and clamped log-std (the same noise draw)."""
        if not fast:
            return self.actor.action_log_prob(observations)
        mean, log_std, _ = self.actor.get_action_dist_params(observations)
        return squashed_gaussian_sample(mean, log_std)

    def actor_loss_gradient_norms(self, batch_size: int = 256, seed: int = 0) -> dict[str, float]:
        """How strongly each actor-loss term pulls on the actor's output (issue 30's check
        that L_sim reaches the actor at a scale comparable to the Q term).

        On ``batch_size`` replay observations (indices drawn with their own generator from
        ``seed``: the training's random streams are untouched, so a resumed run logs the same
        values) and the policy's deterministic (mean) action a there: the mean over the batch
        of the per-sample gradient norm |d l_b / d a_b| of each term of Eq.
        actor_final_compact — ``grad_q`` for the SAC term's -Q(s, a) (the entropy term does
        not depend on the squashed action), ``grad_sim`` for lambda_sim L_sim and ``grad_hap``
        for lambda_hap L_hap (only the terms the method uses; each batch-mean loss's gradient
        times the batch size, so every norm is per sample). Raw action units. Empty before
        the replay buffer holds a transition. With L_hap also its pull on the samples
        outside C_safe (`HapPrior.outside_threshold`): ``hap_active_fraction`` and
        ``grad_hap_active`` (`active_hap_norms`).
        """
        buffer = self.replay_buffer
        assert buffer is not None  # set up with the model
        size = buffer.buffer_size if buffer.full else buffer.pos
        if size == 0:
            return {}
        rng = np.random.default_rng(seed)
        indices = rng.integers(0, size, batch_size)
        stored = cast("dict[str, np.ndarray]", buffer.observations)  # a Dict replay buffer
        observations = {
            key: th.as_tensor(values[indices, 0], device=self.device)
            for key, values in stored.items()
        }
        with th.no_grad():
            mean_actions = self.actor(observations, deterministic=True)
        actions = mean_actions.detach().requires_grad_(True)
        self.critic.requires_grad_(False)
        try:
            q_values = th.cat(self.critic(observations, actions), dim=1)
            min_q = th.min(q_values, dim=1).values
            (grad_q,) = th.autograd.grad(-min_q.sum(), actions)  # per sample: d(-Q_b)/d a_b
        finally:
            self.critic.requires_grad_(True)
        norms = {"grad_q": float(grad_q.norm(dim=1).mean())}
        regulariser: Any = self.regulariser  # an ActorRegulariser (duck-typed: term_gradients)
        if regulariser is not None and hasattr(regulariser, "term_gradients"):
            terms = regulariser.term_gradients(observations["aux"], actions.detach())
            weights = regulariser.weights
            for name, key, weight in (
                ("l_sim", "grad_sim", weights.lambda_sim),
                ("l_hap", "grad_hap", weights.lambda_hap if regulariser.hap_prior else 0.0),
            ):
                if weight > 0 and name in terms:
                    norms[key] = float((terms[name] * batch_size).norm(dim=1).mean())
            if "grad_hap" in norms:
                from distgprl.agents.gradient_norms import active_hap_norms

                norms.update(active_hap_norms(terms["l_hap"], batch_size, terms.get("hap_outside")))
        return norms

    def _setup_learn(self, *args, **kwargs):
        # distgprl: SB3's default logger for verbose=0 without tensorboard still creates an
        # empty tempdir/SB3-<time> folder per learn(); record in memory only instead.
        if not self._custom_logger and self.verbose == 0 and self.tensorboard_log is None:
            self.set_logger(Logger(folder=None, output_formats=[]))
        return super()._setup_learn(*args, **kwargs)

    def _excluded_save_params(self) -> list[str]:
        # The regulariser is rebuilt from the task and config, never pickled.
        return [
            *super()._excluded_save_params(),
            "regulariser",
            "entropy_schedule",
            "_update_cache",
        ]

    @classmethod
    def load_saved(cls, path, env=None) -> RegularisedSAC:
        """A saved model on the CPU; its regulariser and entropy schedule, never pickled, are
        left unset (attach them again to train on, as `distgprl.experiments.checkpoints` does)."""
        return cls.load(
            path,
            env=env,
            device="cpu",
            custom_objects={"regulariser": None, "entropy_schedule": None},
        )
