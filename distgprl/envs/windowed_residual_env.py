"""ProMP-RRL's object-centric ProMP and its demonstration sets (`load_task_promp`: the 20
expert demonstrations of Table I's ProMP-RRL, or the one demonstration's conditioned copies),
and the windowed-weights residual env of the exploration methods ``promp-rrl-windowed`` and
``promp-rrl-expert`` (`ResidualEnv`; Carvalho et al. 2022; Johannink et al. 2018). Table I's
ProMP-RRL is residual RL at 10 Hz: `distgprl.envs.residual_control_env`.

Env ids: ``ProMPRRL-DCP-v<N>`` and ``ProMPRRL-DBM-v<N>`` (`ResidualEnv`), N the environment
version (registered in `distgprl.envs`).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from distgprl.adaptation.trajectories import ResidualProMPTrajectory, variance_gate
from distgprl.config_types import EnvConfig
from distgprl.envs.via_point_env import AdaptationEnv
from distgprl.errors import UserInputError
from distgprl.methods import PROMP_DEMONSTRATIONS, MethodSpec, get_method
from distgprl.skill.demos import (
    SET_INDEX,
    DemonstrationSetEntry,
    load_demonstration,
    load_demonstration_set,
)
from distgprl.skill.promp import ObjectCentricProMP

if TYPE_CHECKING:
    from distgprl.sim.tasks.base import TaskSpec

__all__ = [
    "ResidualEnv",
    "check_demonstrations_succeed",
    "expert_demonstration_set",
    "load_task_promp",
    "one_demonstration_set",
]

DEMONSTRATION_SOURCES = ("one", "expert")

ONE_DEMONSTRATION_TC_SEED = 20_251_201
"""Seed of the training-distribution TCs the one demonstration is conditioned on to give a
``one``-demonstration ProMP-RRL method its demonstration set (`one_demonstration_set`: the
gate of ``promp-rrl-1demo``, the ProMP of ``promp-rrl-windowed``; distinct from the evaluation
and learning-curve seeds)."""

ONE_DEMONSTRATION_SET_SIZE = PROMP_DEMONSTRATIONS["expert"]
"""As many conditioned copies as the expert set has demonstrations."""


def one_demonstration_set(task: str) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray]:
    """The task's one demonstration, conditioned on ``ONE_DEMONSTRATION_SET_SIZE`` TCs drawn
    from the task's training distribution: (demos as (times, poses) pairs, object offsets (K, 3)).

    Every GP method gets exactly this information: the one demonstration and the observed
    TC, conditioned by moving the demonstration with the object from the interaction time on
    (`distgprl.sim.tasks.base.condition_by_translation`, the GP skill's conditioning rule on
    the dense demonstration). No expert plans, no success filter. Expressed in each object's
    frame, the copies coincide after the interaction time and differ before it, where the
    translation ramps in: that is the variability an object-centric ProMP can learn from one
    demonstration (Carvalho et al. fit it to demonstrations for several object poses).
    """
    from distgprl.sim.tasks import get_task
    from distgprl.sim.tasks.base import condition_by_translation

    spec = get_task(task)
    demo = load_demonstration(spec.demo_path)
    rng = np.random.default_rng(ONE_DEMONSTRATION_TC_SEED)
    demos, offsets = [], []
    for _ in range(ONE_DEMONSTRATION_SET_SIZE):
        offset = np.asarray(spec.sample_tc(rng).object_offset, dtype=float)
        poses = condition_by_translation(
            demo.times,
            demo.poses,
            offset,
            spec.interaction_time,
            goal_fixed_in_world=spec.goal_fixed_in_world,
        )
        demos.append((demo.times, poses))
        offsets.append([*offset, 0.0])
    return demos, np.asarray(offsets)


def expert_demonstration_set(
    task: str, folder: str | Path | None = None
) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray]:
    """The 20 TC-aware scripted-expert demonstrations of ``folder`` (default the task's
    shipped ``distgprl/data/demos/<task>_varied/``), the set Table I's ProMP-RRL fits (the
    paper's §V-B: "an object-centric ProMP over 20 demonstrated trajectories"): (demos as
    (times, poses) pairs, object offsets (K, 3), m).

    The set must be exactly ``PROMP_DEMONSTRATIONS["expert"]`` = 20 demonstrations
    (`distgprl.skill.demos.load_demonstration_set`), each successful and collision-free
    for its own TC: every one is executed in the task's simulation on its TC
    (`distgprl.sim.experts.run_demonstration`, as the expert kept it when it wrote the set;
    about 0.5 s for 20).

    Raises:
        UserInputError: one line naming the folder, ``tcs.json`` or the demonstration at fault.
    """
    from distgprl.sim.tasks import get_task

    spec = get_task(task)
    folder = spec.varied_demo_dir if folder is None else Path(folder)
    entries = load_demonstration_set(folder, PROMP_DEMONSTRATIONS["expert"], task=task)
    check_demonstrations_succeed(spec, entries)
    demos = [(e.demonstration.times, e.demonstration.poses) for e in entries]
    offsets = np.array([[*e.tc["object_offset"], 0.0] for e in entries])
    return demos, offsets


def check_demonstrations_succeed(spec: TaskSpec, entries: list[DemonstrationSetEntry]) -> None:
    """Execute each demonstration in a fresh simulation of ``spec`` on its TC; a
    `UserInputError` names the first that fails the task or collides."""
    from distgprl.sim.experts import run_demonstration
    from distgprl.sim.tasks.base import TaskConfig

    sim = spec.make_sim()
    try:
        for entry in entries:
            demo = entry.demonstration
            tc = TaskConfig.from_dict(entry.tc)
            success, collision, _ = run_demonstration(sim, tc, demo.times, demo.poses)
            if collision or not success:
                outcome = "collides" if collision else "does not complete the task"
                raise UserInputError(
                    f"{entry.path}: the demonstration {outcome} for its TC in {SET_INDEX}; "
                    f"ProMP-RRL's demonstrations must be successful and collision-free"
                )
    finally:
        sim.close()


@lru_cache(maxsize=8)
def load_task_promp(task: str, source: str = "one") -> ObjectCentricProMP:
    """The object-centric ProMP of ProMP-RRL: fitted to `expert_demonstration_set`
    (``"expert"``, the 20 demonstrations of Table I's ProMP-RRL) or to
    `one_demonstration_set` (``"one"``, 20 TC-conditioned copies of the one demonstration:
    the gate of the study method ``promp-rrl-1demo``).

    Each demonstration is expressed in its object's frame by subtracting the object's start
    offset (x, y, 0) before the fit.
    """
    if source == "one":
        demos, offsets = one_demonstration_set(task)
    elif source == "expert":
        demos, offsets = expert_demonstration_set(task)
    else:
        raise ValueError(f"source must be one of {DEMONSTRATION_SOURCES}, got {source!r}")
    return ObjectCentricProMP.fit(demos, offsets)


class ResidualEnv(AdaptationEnv):
    """Residual RL on the ProMP nominal trajectory, with the Dist-GPRL episode structure.

    The nominal trajectory is the object-centric ProMP's mean for the observed object
    start offset, conditioned to start at the robot's current pose. The ProMP is
    `load_task_promp`'s for the method's ``demonstrations``: ``"one"`` (the one
    demonstration conditioned on training-distribution TCs) or ``"expert"`` (20 TC-aware
    expert demonstrations, e.g. the exploration method ``promp-rrl-expert``). The policy
    learns a residual correction on top of it (Johannink et al. 2018):

        pose(tau) = nominal(tau) + sum_j g_j w_j phi_j(tau),

    with N = 15 Gaussian radial basis functions centred at the via-point times (width =
    their spacing), *normalised* to sum to 1 (a residual of the same size on every weight
    moves the pose by exactly that size, the GP methods' total range), the ProMP's
    `variance_gate` g_j, and residual weights w (N x 6, m and rad), all zero at the start
    of an episode (a zero action executes the nominal trajectory exactly). RL step k adds
    to the weights of the same windows as Dist-GPRL (W_k, L = 5, one-point overlap)
    from a raw action a in [-1, 1]^(L x 6) scaled per axis — no covariance transform —
    and the same segments are executed with the same blending (the overlap via-point's
    weight accumulates both windows' updates).

    **Observation** (``state``): the residual-corrected poses at the window's basis
    centres (L x 6, standardised as in `AdaptationEnv`), the EDF clearance at them (L),
    e_o (3), e_g (3) and the phase (1): the same layout and sizes as `AdaptationEnv`.

    **Reward**: the task reward only, r = r_progress + r_success + r_collision (the
    collision penalty included); no distance shaping, no HAP prior, no L_sim.

    **Start** and **End**: as `AdaptationEnv` (the same ``info`` at the end).
    What each environment version changed for this env: CHANGELOG.md.
    """

    def __init__(
        self,
        task: str,
        config: EnvConfig | None = None,
        render_mode=None,
        method: str | MethodSpec = "promp-rrl-windowed",
    ) -> None:
        spec = method if isinstance(method, MethodSpec) else get_method(method)
        if spec.action_mode != "residual":
            raise ValueError(f"method {spec.name} is not a residual method")
        self.promp = load_task_promp(task, spec.demonstrations)
        # the basis centres are the via-point times, evenly spaced (GPSkill's)
        centres = np.linspace(0.0, 1.0, (config or EnvConfig()).n_via_points)
        self._gate = variance_gate(self.promp, centres)
        super().__init__(task, spec, config, render_mode=render_mode)

    def trajectory_model(self) -> ResidualProMPTrajectory:
        """The residual on the ProMP nominal, basis centres at the via-point times."""
        return ResidualProMPTrajectory(
            self.promp, self.skill.via_times, self._gate, self.skill.duration
        )

    def residual_basis(self, tau: np.ndarray) -> np.ndarray:
        """The gated, normalised residual basis at normalised times ``tau`` (m,): (m, N);
        the residual's pose offset at ``tau`` is ``residual_basis(tau) @ gamma``."""
        return cast(ResidualProMPTrajectory, self.window_plan.model).basis(tau)

    def nominal(self, tau: np.ndarray) -> np.ndarray:
        """The episode's nominal trajectory (the conditioned ProMP mean) at ``tau`` (m,),
        shape (m, 6), m and rad."""
        return cast(ResidualProMPTrajectory, self.window_plan.model).nominal(tau)
