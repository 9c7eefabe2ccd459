"""The method registry (DESIGN §6): every method is fully described by data.

The environment, the SAC subclass and the runner read these switches; no method is
special-cased anywhere else. ``demo`` is the unadapted reference (the TC-conditioned
demonstration executed as is).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Literal

from distgprl.errors import UserInputError

ActionMode = Literal["window", "global", "residual", "residual-control", "none"]
EntropyMode = Literal["auto", "anneal"]


@dataclass(frozen=True)
class MethodSpec:
    """One row of the methods table.

    Attributes:
        name: registry key (CLI name).
        label: name used in tables and figures.
        action_mode: ``window`` (L via-points per RL step), ``global`` (all adaptable
            via-points every step), ``residual`` (ProMP-RRL residual weights on a nominal
            trajectory, at the windowed steps), ``residual-control`` (ProMP-RRL as residual
            RL: a Cartesian residual at 10 Hz, `distgprl.envs.residual_control_env`), ``none`` (no
            learning).
        covariance_transform: apply Delta Gamma = S_W a (Eq. transformed_action).
        distance_rewards: add r_sd and lambda_ga r_ga (Eq. total_reward).
        hap_prior: add lambda_hap L_hap to the actor loss (Eq. actor_final_compact).
        similarity_loss: add lambda_sim L_sim to the actor loss.
        hold_tc_via_point: keep the TC-conditioned interaction via-point fixed (GPRL).
        signature_reward: add GPRL's signature-similarity reward.
        entropy: ``auto`` (SAC's automatic temperature) or ``anneal`` (GPRL schedule).
        trainable: whether the method trains a policy.
        demonstrations: what a residual method's object-centric ProMP is fitted to (only
            ``residual`` and ``residual-control`` fit one): ``expert`` — the 20 shipped
            expert demonstrations (``distgprl/data/demos/<task>_varied/``, each successful
            and collision-free for its own TC), the ProMP of both the nominal and the
            variance gate (Table I's ProMP-RRL as the paper's §V-B defines it, "an
            object-centric ProMP over 20 demonstrated trajectories"); ``one`` — the one
            demonstration every GP method gets: for ``residual-control`` the nominal is the
            ProMP of that demonstration itself and the gate's ProMP is fitted to 20 copies
            of it conditioned on training TCs (the study method ``promp-rrl-1demo``). How
            many distinct demonstrations that is: `demonstration_count`.
        episode_range: a global action's per-step scale is the configured one divided by
            the number of RL steps, so that over an episode a via-point can move as far as
            a windowed method's (DESIGN §3: windowing and correlation are the only
            difference). Without it a global action, added to every via-point at each of
            the 3 steps, reaches three times the windowed range.
    """

    name: str
    label: str
    action_mode: ActionMode
    covariance_transform: bool = False
    distance_rewards: bool = False
    hap_prior: bool = False
    similarity_loss: bool = False
    hold_tc_via_point: bool = False
    signature_reward: bool = False
    entropy: EntropyMode = "auto"
    trainable: bool = True
    episode_range: bool = False
    demonstrations: Literal["one", "expert"] = "one"

    @property
    def fits_promp(self) -> bool:
        """Whether the method fits an object-centric ProMP (the residual action modes)."""
        return self.action_mode in ("residual", "residual-control")

    @property
    def demonstration_count(self) -> int:
        """How many distinct demonstrations the method's ProMP is fitted on
        (`PROMP_DEMONSTRATIONS`; 0 for a method without a ProMP)."""
        return PROMP_DEMONSTRATIONS[self.demonstrations] if self.fits_promp else 0

    def to_dict(self) -> dict:
        """The spec as a dict (hashed into every run's config hash, recorded in its
        ``config.json``). Fields added after results were committed appear only when they
        differ from the default that reproduces the old behaviour, so that those runs keep
        their hash. A method that fits a ProMP also records ``demonstration_count``, how
        many demonstrations it is fitted on."""
        data = asdict(self)
        for field, default in HASH_STABLE_DEFAULTS.items():
            if data[field] == default:
                del data[field]
        if self.fits_promp:
            data["demonstration_count"] = self.demonstration_count
        return data


PROMP_DEMONSTRATIONS: dict[str, int] = {"one": 1, "expert": 20}
"""Distinct demonstrations per `MethodSpec.demonstrations` source: the one shipped
demonstration, or the 20 demonstrated trajectories of the paper's ProMP-RRL (§V-B). The
loader refuses an ``expert`` set of any other size (`distgprl.envs.windowed_residual_env`)."""


#: Fields added to `MethodSpec` after committed results, with their old-behaviour default.
HASH_STABLE_DEFAULTS: dict[str, object] = {"episode_range": False, "demonstrations": "one"}


METHODS: dict[str, MethodSpec] = {
    spec.name: spec
    for spec in (
        MethodSpec(
            "gprl",
            "GPRL",
            "global",
            hold_tc_via_point=True,
            signature_reward=True,
            entropy="anneal",
            episode_range=True,
        ),
        MethodSpec("promp-rrl", "ProMP-RRL", "residual-control", demonstrations="expert"),
        MethodSpec("promp-rrl-1demo", "ProMP-RRL (1 demo)", "residual-control"),
        MethodSpec("promp-rrl-windowed", "ProMP-RRL (windowed weights)", "residual"),
        MethodSpec(
            "promp-rrl-expert", "ProMP-RRL (20 expert demos)", "residual", demonstrations="expert"
        ),
        MethodSpec(
            "dist-gprl-global",
            "Dist-GPRL-Global",
            "global",
            distance_rewards=True,
            hap_prior=True,
            similarity_loss=True,
            episode_range=True,
        ),
        MethodSpec(
            "gprl-d",
            "GPRL-D",
            "window",
            covariance_transform=True,
            distance_rewards=True,
            similarity_loss=True,
        ),
        MethodSpec(
            "gprl-h",
            "GPRL-H",
            "window",
            covariance_transform=True,
            hap_prior=True,
            similarity_loss=True,
        ),
        MethodSpec(
            "dist-gprl",
            "Dist-GPRL (ours)",
            "window",
            covariance_transform=True,
            distance_rewards=True,
            hap_prior=True,
            similarity_loss=True,
        ),
        MethodSpec(
            "dist-gprl-nocov",
            "Dist-GPRL-NoCov",
            "window",
            covariance_transform=False,
            distance_rewards=True,
            hap_prior=True,
            similarity_loss=True,
        ),
        MethodSpec("demo", "Demo (no adaptation)", "none", trainable=False),
        MethodSpec(
            "promp-nominal",
            "ProMP nominal (no residual)",
            "residual-control",
            trainable=False,
            demonstrations="expert",
        ),
        MethodSpec(
            "promp-nominal-1demo",
            "ProMP nominal (1 demo, no residual)",
            "residual-control",
            trainable=False,
        ),
    )
}

#: Table I row order (the paper's order, then the ablation and the reference).
TABLE_ORDER: tuple[str, ...] = (
    "gprl",
    "promp-rrl",
    "dist-gprl-global",
    "gprl-d",
    "gprl-h",
    "dist-gprl",
    "dist-gprl-nocov",
    "demo",
    "promp-nominal",
)

EXPLORATION_METHODS: tuple[str, ...] = ("promp-rrl-windowed", "promp-rrl-expert")
"""Methods outside Table I and the default sweep (run them by name): ``promp-rrl-windowed`` adapts
the residual ProMP weights at the three windowed steps (not residual RL) on the one
demonstration; ``promp-rrl-expert`` the same on the 20 expert
demonstrations. Table I's ``promp-rrl`` is residual RL (`distgprl.envs.residual_control_env`)."""

STUDY_METHODS: tuple[str, ...] = ("promp-rrl-1demo", "promp-nominal-1demo")
"""Methods reported beside Table I, not in it, and outside the default sweep (run them by
name, e.g. ``distgprl sweep --preset paper --methods promp-rrl-1demo``): ``promp-rrl-1demo``
is the same 10 Hz residual RL as Table I's ``promp-rrl``, its
nominal the ProMP of the one demonstration every GP method gets, its gate's ProMP fitted to
20 TC-conditioned copies of it (the paper's §V-A "a single expert demonstration for each
task", where its §V-B defines ProMP-RRL on 20 demonstrated trajectories;
protocol rule 3, "ProMP-RRL as the paper defines it") — and ``promp-nominal-1demo`` its
nominal with zero residual."""


REPORTED_METHODS: tuple[str, ...] = tuple(name for name in METHODS if name not in STUDY_METHODS)
"""The methods whose runs a preset's reports read by default: every one but `STUDY_METHODS`,
whose runs share the preset's folder and are read only by the study's own table."""

NO_SAFETY_LAYER = (
    "the plan-repair evaluation in simulation (Table I with the safety layer) re-plans a "
    "window's via-point plan; a residual-control method (promp-rrl, "
    "promp-nominal) commands a 10 Hz residual with no window plan: not implemented (its twin "
    "trials check and re-time each 0.1 s step instead, `distgprl hardware`)"
)
"""Why `has_via_point_plan` methods are the only ones the simulated safety-layer evaluation
(`distgprl.experiments.safety_layer_evaluation`) runs."""


def has_via_point_plan(spec: MethodSpec) -> bool:
    """Whether ``spec`` plans each window ahead (via-points or residual weights), as the
    simulated safety-layer evaluation needs (every action mode but ``residual-control``;
    the twin trials run every method, residual control one 0.1 s step at a time)."""
    return spec.action_mode != "residual-control"


def get_method(name: str) -> MethodSpec:
    """The registered method ``name``; a `UserInputError` lists the valid names."""
    try:
        return METHODS[name]
    except KeyError:
        raise UserInputError(
            f"unknown method {name!r}; valid methods: {', '.join(METHODS)}"
        ) from None
