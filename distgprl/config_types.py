"""The configuration's types: frozen dataclasses with the paper's defaults (one source for
each default), and the environment version every run records. `distgprl.config` loads them
from presets and validates them; import them from there.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

__all__ = [
    "ENVIRONMENT_VERSION",
    "HASH_STABLE_DEFAULTS",
    "Config",
    "EnvConfig",
    "RunConfig",
    "SACConfig",
]

ENVIRONMENT_VERSION = 8
"""The environment version every run records (it enters the config hash, so runs of an older
version are stale). What each version changed, and why: CHANGELOG.md and docs/FINDINGS.md.
Docstrings cite the current protocol's rules as "protocol rule N" (their text:
docs/findings/environment-v8.md "Protocol v8") and the earlier protocol's rules that still
stand as "docs/findings/protocol.md, rule N"."""


@dataclass(frozen=True)
class EnvConfig:
    """The adaptation MDP (paper §IV, DESIGN §3).

    Attributes:
        n_via_points: N (paper: 15).
        window_size: L (paper: 5); windows overlap by one via-point.
        n_windows: RL steps per episode (paper: 3; the results schema records exactly three,
            `distgprl.schema.N_WINDOWS`).
        correlation_lambda: lambda of S = K (K + lambda I)^-1 (paper: 1e-2).
        correlation_length_scale: length scale (normalised time) of the kernel matrix K in
            S only; 0 (default) = the kernel fitted to the demonstration, as in every
            `paper` run. The paper gives no K beyond Eq. global_S; with the fitted length
            scales (just under the via-point spacing) S_W is nearly the identity
            (docs/FINDINGS.md, "Covariance transform"), so this lets a run use a K that
            does correlate neighbouring via-points. The trajectory GP is unchanged.
        covariance_scale: the K of S (`distgprl.adaptation.layout.COVARIANCE_SCALES`).
            ``"zero-mean"`` (Table I) — K_tt is the covariance matrix of the
            paper's zero-mean GP (Eq. 1), per axis fitted by marginal likelihood to the raw
            demonstration (constant axes: 0.2 rad scale); ``"signal"`` (study preset
            ``operator-signal``) — the standardised GP's variance times the axis's
            demonstration variance; ``"unit"`` (``operator-unit``) — the unit-variance
            correlation matrix; ``"correlation"`` (``operator-correlation``) — the
            zero-mean operator with each row divided by its row sum (reach without shrink);
            ``"signal-uncoupled"`` (``operator-signal-uncoupled``, the operator study's
            control, not a reading of the paper) — the diagonal of the ``"signal"``
            operator's row gains (its reach without its coupling).
        action_scale_rule: how the raw action's per-axis scale is set (the paper does not
            give it). ``"reach"`` (Table I): per task and axis, so that under the
            Table I operator (``covariance_scale="zero-mean"``, whatever operator the run
            uses) every windowed via-point can move max(TC range on that axis, minimum
            reach) in the one step that adapts it (`distgprl.adaptation.layout.reach_scales`;
            docs/findings/protocol.md, rule 2); ``"fixed"``: the two scales below.
        minimum_position_reach: the least one-step reach (m) rule ``"reach"`` gives a
            position axis (approach via-points must follow the objects by about 10 cm).
        minimum_rotation_reach: likewise for a rotation axis, rad.
        position_action_scale: m of via-point change per unit raw action with rule
            ``"fixed"``.
        rotation_action_scale: rad of via-point change per unit raw action (rule
            ``"fixed"``).
        lambda_ga: weight of the gradient-alignment reward (paper: 0.2).
        progress_weight: r_tc weight of the change in task progress (in [0, 1]): the whole
            task's progress is worth 10, so that lambda_ga r_ga can pay at most 3 % of a
            success's r_tc (`distgprl.reward_scale`, bound (a)) and an episode that never
            attempts the task earns under 10 % of what the demonstration earns (bound (b)).
        success_bonus: r_tc bonus on success at the end of the episode (10, as the progress).
        collision_penalty: r_tc penalty for a segment with a collision (10, as the progress).
        collision_ends_episode: a collision stops execution at that control period and
            ends the episode, as a protective stop ends a hardware trial; success is then
            task completion without collision (False: execution pushes on through
            kinematic obstacles and success ignores collisions).
        sd_beta: beta of the hyperbolic clearance penalty (Eq. safety_reward):
            collision_penalty x eps / (sd_samples_per_segment x 50 tool points) = 5e-4, so
            the whole tool held at distance d for a whole segment costs collision_penalty x
            eps / (d + eps): the collision penalty at contact, a quarter of it at d_min; one
            tool point 1/50 of that.
        sd_d_min: d_min of Eq. safety_reward, m.
        sd_epsilon: epsilon of Eq. safety_reward, m.
        sd_samples_per_segment: instants per executed segment at which the tool points
            are checked against the EDF for r_sd (the segment is executed in as many
            chunks).
        blend_fraction: fraction of a segment over which a jump between the robot's
            pose and the re-planned trajectory (caused by updating the overlap
            via-point) is blended out with a minimum-jerk weight.
        clearance_clip: observed EDF clearances are clipped to this value, m.
        clearance_scale: observed clearances are divided by this, m.
        relative_position_scale: observed e_o and e_g are divided by this, m.
        clearance_timing: when the obstacles are taken for the window via-points' EDF
            clearances and gradients (state ``c`` and r_ga): ``"predicted"`` (default)
            at the time the trajectory reaches each via-point, along the moving
            obstacles' known paths; ``"current"`` (the paper read literally) at
            the observation instant.
        signature_weight: GPRL's signature-similarity reward weight (a tenth of r_tc's
            unit, like lambda_ga's share of it).
        signature_depth: truncation level of the path signature (GPRL).
        signature_scale: distance scale of the signature similarity (GPRL).
    """

    n_via_points: int = 15
    window_size: int = 5
    n_windows: int = 3
    correlation_lambda: float = 1e-2
    correlation_length_scale: float = 0.0
    covariance_scale: str = "zero-mean"
    action_scale_rule: str = "reach"
    minimum_position_reach: float = 0.1
    minimum_rotation_reach: float = 0.05
    position_action_scale: float = 0.1
    rotation_action_scale: float = 0.05
    lambda_ga: float = 0.2
    progress_weight: float = 10.0
    success_bonus: float = 10.0
    collision_penalty: float = 10.0
    collision_ends_episode: bool = True
    sd_beta: float = 5e-4  # collision_penalty x eps / (4 instants x 50 tool points)
    sd_d_min: float = 0.03
    sd_epsilon: float = 0.01
    sd_samples_per_segment: int = 4
    blend_fraction: float = 0.3
    clearance_clip: float = 0.3
    clearance_scale: float = 0.05
    relative_position_scale: float = 0.1
    clearance_timing: str = "predicted"
    signature_weight: float = 1.0
    signature_depth: int = 3
    signature_scale: float = 0.05


@dataclass(frozen=True)
class SACConfig:
    """SAC (Haarnoja et al. 2018 defaults) and the regularised actor loss.

    Attributes:
        learning_rate: Adam step size of the actor, the critics and the entropy coefficient.
        buffer_size: replay buffer capacity, transitions (RL steps).
        batch_size: transitions per gradient step.
        gamma: discount per RL step (one window).
        tau: Polyak coefficient of the target critics' soft update, per gradient step.
        learning_starts: RL steps of uniformly random actions before the first update.
        train_freq: RL steps between updates.
        gradient_steps: gradient steps per update.
        net_arch: hidden units per layer of the actor and of each critic.
        lambda_sim: weight of L_sim (paper: 0.5).
        lambda_hap: weight of L_hap (paper: 0.2).
        lambda_velocity: lambda_v of Eq. sim_compact (the paper does not give it; set once,
            never tuned).
        lambda_acceleration: lambda_a of Eq. sim_compact, per unit of *relative* L1
            acceleration error (the L1 term divided by the demonstration's mean L1
            acceleration, so both terms are dimensionless). The paper gives neither lambda_v nor
            lambda_a, only lambda_sim: equal unit weights of two dimensionless terms, set
            from the units, never tuned.
        n_similarity_samples: T, trajectory samples for L_sim.
        hap_k, hap_temperature, hap_n_query: k, tau (m) and N_q of Eq. hap_compact.
        hap_hinge: False (default): L_hap as Eq. hap_compact writes it, the soft-min in
            metres; True: each query's soft-min hinged at its value at the centre of a fully
            safe grid cell and divided by the HAP grid step (a variant, not Table I's).
        anneal_start, anneal_end: GPRL's entropy coefficient, decayed exponentially
            from start to end over the run (set relative to r_tc's unit).
        ent_coef_init: initial value of SAC's automatically tuned entropy coefficient
            (SB3 ``ent_coef="auto_<init>"``). SB3's default 1.0 makes the entropy bonus of a
            30-D action dwarf this task's rewards for the first ~15k steps; 0.1 keeps the
            automatic tuning of Haarnoja et al. but starts at the scale of the rewards
            (a hundredth of r_tc's unit).
    """

    learning_rate: float = 3e-4
    buffer_size: int = 1_000_000
    batch_size: int = 256
    gamma: float = 0.99
    tau: float = 0.005
    learning_starts: int = 1000
    train_freq: int = 1
    gradient_steps: int = 1
    net_arch: tuple[int, ...] = (256, 256)
    lambda_sim: float = 0.5
    lambda_hap: float = 0.2
    lambda_velocity: float = 1.0
    lambda_acceleration: float = 1.0
    n_similarity_samples: int = 50
    hap_k: int = 8
    hap_temperature: float = 0.05
    hap_n_query: int = 20
    hap_hinge: bool = False
    anneal_start: float = 0.2
    anneal_end: float = 0.002
    ent_coef_init: float = 0.1


@dataclass(frozen=True)
class RunConfig:
    """Training and evaluation sizes.

    Attributes:
        total_steps: RL steps (3 per episode).
        eval_every: learning-curve evaluation period, steps.
        curve_episodes: TCs of the fixed learning-curve set evaluated each time.
        eval_episodes: evaluation TCs for the final evaluation (paper: 100).
        checkpoint_every: checkpoint period (model + replay buffer), steps.
        torch_threads: torch intra-op threads per run.
    """

    total_steps: int = 30_000
    eval_every: int = 1_500
    curve_episodes: int = 20
    eval_episodes: int = 100
    checkpoint_every: int = 3_000
    torch_threads: int = 1


@dataclass(frozen=True)
class Config:
    """A resolved configuration (what `config.json` of a run records).

    Attributes:
        preset: the preset's name (a shipped preset, or the stem of a ``--preset-file``
            file), with the ``--set`` overrides it carries (``paper+sac.batch_size=128``).
        env: the adaptation MDP (`EnvConfig`).
        sac: SAC and the regularised actor loss (`SACConfig`).
        run: training and evaluation sizes (`RunConfig`).
    """

    preset: str = "paper"
    env: EnvConfig = field(default_factory=EnvConfig)
    sac: SACConfig = field(default_factory=SACConfig)
    run: RunConfig = field(default_factory=RunConfig)

    def to_dict(self) -> dict[str, Any]:
        """The configuration as a dict (what `config.json` records and the run's config hash
        covers). Fields added after results were committed appear only when they differ from
        the default that reproduces the old behaviour, so that those runs keep their hash."""
        data = asdict(self)
        for (section, key), default in HASH_STABLE_DEFAULTS.items():
            if data[section][key] == default:
                del data[section][key]
        return data


#: Fields added to the configuration after committed results, with their old-behaviour default.
HASH_STABLE_DEFAULTS: dict[tuple[str, str], Any] = {("env", "correlation_length_scale"): 0.0}
