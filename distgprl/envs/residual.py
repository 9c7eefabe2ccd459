"""ProMP-RRL: residual SAC on an object-centric ProMP (Carvalho et al. 2022; Johannink et al. 2018).

Env ids: ``ProMPRRL-DCP-v3`` and ``ProMPRRL-DBM-v3``.
"""

from __future__ import annotations

import json
from functools import lru_cache

import numpy as np

from distgprl.config import EnvConfig
from distgprl.envs.adaptation import AdaptationEnv
from distgprl.methods import get_method
from distgprl.skill.demos import load_demonstration
from distgprl.skill.promp import ObjectCentricProMP


@lru_cache(maxsize=4)
def load_task_promp(task: str) -> ObjectCentricProMP:
    """The object-centric ProMP fitted to the task's 20 varied demonstrations.

    Each demonstration is expressed in its object's frame by subtracting the object's
    start offset (x, y, 0) of the TC it was made for (``tcs.json`` beside the files).
    """
    from distgprl.sim.tasks import get_task

    folder = get_task(task).varied_demo_dir
    tcs = json.loads((folder / "tcs.json").read_text())
    demos, offsets = [], []
    for name, tc in zip(tcs["files"], tcs["tcs"], strict=True):
        demo = load_demonstration(folder / name)
        demos.append((demo.times, demo.poses))
        offsets.append([*tc["object_offset"], 0.0])
    return ObjectCentricProMP.fit(demos, np.asarray(offsets))


class ResidualEnv(AdaptationEnv):
    """Residual RL on the ProMP nominal trajectory, with the Dist-GPRL episode structure.

    The nominal trajectory is the object-centric ProMP's mean for the observed object
    start offset, conditioned to start at the robot's current pose. The policy learns a
    residual correction on top of it (Johannink et al. 2018):

        pose(tau) = nominal(tau) + sum_j w_j phi_j(tau),

    with N = 15 Gaussian radial basis functions phi_j centred at the via-point times
    (width = their spacing) and residual weights w (N x 6, m and rad), all zero at the
    start of an episode (a zero action executes the nominal trajectory exactly). RL step
    k adds to the weights of the same windows as Dist-GPRL (W_k, L = 5, one-point overlap)
    from a raw action a in [-1, 1]^(L x 6) scaled per axis — no covariance transform —
    and the same segments are executed with the same blending (the overlap via-point's
    weight accumulates both windows' updates).

    **Observation** (``state``): the residual-corrected poses at the window's basis
    centres (L x 6, standardised as in `AdaptationEnv`), the EDF clearance at them (L),
    e_o (3), e_g (3) and the phase (1): the same layout and sizes as `AdaptationEnv`.

    **Reward**: the task reward only, r = r_progress + r_success + r_collision (the
    collision penalty included); no distance shaping, no HAP prior, no L_sim.

    **Versions**: v3 — position action scale 0.1 m (see `AdaptationEnv`). v2 — time-indexed
    clearances and O(1) observation units (see `AdaptationEnv`). v1 — floored observation
    scale. v0 — first release.
    """

    def __init__(self, task: str, config: EnvConfig | None = None, render_mode=None) -> None:
        self.promp = load_task_promp(task)
        super().__init__(task, get_method("promp-rrl"), config, render_mode=render_mode)

    def _rbf(self, tau: np.ndarray) -> np.ndarray:
        centres = self.skill.via_times
        width = centres[1] - centres[0]
        return np.exp(-0.5 * ((np.asarray(tau)[:, None] - centres[None, :]) / width) ** 2)

    def _parameter_map(self, tau: np.ndarray) -> np.ndarray:
        return self._rbf(tau)

    def _nominal(self, tau: np.ndarray) -> np.ndarray:
        return self._nominal_promp.mean_trajectory(np.clip(tau, 0.0, 1.0), self._object_offset)

    def _segment_base(self, step: int) -> np.ndarray:
        return self._nominal_bases[step]

    def _plan(self, tau: np.ndarray) -> np.ndarray:
        return self._nominal(tau) + self._rbf(tau) @ self.gamma

    def _planned_velocity(self, tau: np.ndarray) -> np.ndarray:
        dense = np.linspace(0.0, 1.0, 400)
        velocity = np.gradient(self._plan(dense), dense * self.skill.duration, axis=0)
        return np.stack([np.interp(tau, dense, velocity[:, a]) for a in range(6)], axis=1)

    def _window_poses(self, indices: np.ndarray) -> np.ndarray:
        return self._plan(self.skill.via_times[indices])

    def _initial_parameters(self, tc) -> np.ndarray:
        self._object_offset = np.r_[np.asarray(tc.object_offset, dtype=float), 0.0]
        # Nominal: ProMP mean for the observed object, conditioned on the start pose.
        self._nominal_promp = self.promp.conditioned(
            0.0, self._start_pose, object_position=self._object_offset
        )
        self._nominal_bases = [self._nominal(tau) for tau, _, _, _ in self._segment_maps]
        return np.zeros((self.skill.n_via_points, 6))
