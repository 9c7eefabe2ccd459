"""The method registry (DESIGN §6): every method is fully described by data.

The environment, the SAC subclass and the runner read these switches; no method is
special-cased anywhere else. ``demo`` is the unadapted reference (the TC-conditioned
demonstration executed as is).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Literal

from distgprl.errors import UserInputError

ActionMode = Literal["window", "global", "residual", "none"]
EntropyMode = Literal["auto", "anneal"]


@dataclass(frozen=True)
class MethodSpec:
    """One row of the methods table.

    Attributes:
        name: registry key (CLI name).
        label: name used in tables and figures.
        action_mode: ``window`` (L via-points per RL step), ``global`` (all adaptable
            via-points every step), ``residual`` (ProMP-RRL residual on a nominal
            trajectory), ``none`` (no learning).
        covariance_transform: apply Delta Gamma = S_W a (Eq. transformed_action).
        distance_rewards: add r_sd and lambda_ga r_ga (Eq. total_reward).
        hap_prior: add lambda_hap L_hap to the actor loss (Eq. actor_final_compact).
        similarity_loss: add lambda_sim L_sim to the actor loss.
        hold_tc_via_point: keep the TC-conditioned interaction via-point fixed (GPRL).
        signature_reward: add GPRL's signature-similarity reward.
        entropy: ``auto`` (SAC's automatic temperature) or ``anneal`` (GPRL schedule).
        trainable: whether the method trains a policy.
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

    def to_dict(self) -> dict:
        return asdict(self)


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
        ),
        MethodSpec("promp-rrl", "ProMP-RRL", "residual"),
        MethodSpec(
            "dist-gprl-global",
            "Dist-GPRL-Global",
            "global",
            distance_rewards=True,
            hap_prior=True,
            similarity_loss=True,
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
)


def get_method(name: str) -> MethodSpec:
    """The registered method ``name``; a `UserInputError` lists the valid names."""
    try:
        return METHODS[name]
    except KeyError:
        raise UserInputError(
            f"unknown method {name!r}; valid methods: {', '.join(METHODS)}"
        ) from None
