"""The two trajectory models a :class:`~distgprl.adaptation.plan.WindowPlan` adapts
(:class:`~distgprl.adaptation.plan.TrajectoryModel`).

:class:`GPSkillTrajectory`: the GP skill's via-points Gamma (N, 6), conditioned on the TC by
moving the interaction via-point and its successors with the object, weighted by
`distgprl.skill.conditioning.conditioning_weights` (DESIGN §2, §8).
:class:`ResidualProMPTrajectory`: ProMP-RRL's residual weights Gamma (N, 6) on the
object-centric ProMP's nominal (`distgprl.envs.windowed_residual_env.ResidualEnv`).
"""

from __future__ import annotations

import numpy as np

from distgprl.adaptation.plan import TaskConfigLike
from distgprl.skill.conditioning import conditioning_weights
from distgprl.skill.gp import GPSkill
from distgprl.skill.promp import ObjectCentricProMP

__all__ = ["GPSkillTrajectory", "ResidualProMPTrajectory", "variance_gate"]


class GPSkillTrajectory:
    """The GP skill as a trajectory model: poses ``mu + M (Gamma - mu)`` at tau.

    Args:
        skill: the task's GP skill.
        interaction_index: the via-point nearest the interaction time (the first one moved
            with the object by the TC conditioning).
        goal_fixed_in_world: the task's goal stays put when the object moves (DCP): the
            via-points after the interaction return linearly to the demonstration's end
            (False keeps them all moved, as on DBM).
    """

    def __init__(
        self, skill: GPSkill, interaction_index: int, goal_fixed_in_world: bool = False
    ) -> None:
        self.skill = skill
        self.interaction_index = int(interaction_index)
        self.weights = conditioning_weights(
            skill.via_times, float(skill.via_times[self.interaction_index]), goal_fixed_in_world
        )

    def parameter_map(self, tau: np.ndarray) -> np.ndarray:
        """M(tau), (m, N): the GP's position map."""
        return self.skill.position_map(tau)

    def condition(self, tc: TaskConfigLike, start_pose: np.ndarray) -> np.ndarray:
        """Demonstration via-points conditioned on ``tc`` (DESIGN §2), via-point 0 the start
        pose (6,): shape (N, 6)."""
        offset = np.r_[np.asarray(tc.object_offset, dtype=float)[:2], 0.0]
        gamma = self.skill.via_points.copy()
        gamma[:, :3] += self.weights[:, None] * offset  # w(tau_i) per via-point
        gamma[0] = start_pose
        return gamma

    def offset(self, tau: np.ndarray, parameter_map: np.ndarray) -> np.ndarray:
        """mu - (M 1) mu^T at ``tau``, (m, 6) (independent of the TC)."""
        mean = self.skill.prior_mean
        offset: np.ndarray = mean[None, :] * (1.0 - parameter_map.sum(axis=1))[:, None]
        return offset

    def position(self, parameters: np.ndarray, tau: np.ndarray) -> np.ndarray:
        return self.skill.position(parameters, tau)

    def velocity(self, parameters: np.ndarray, tau: np.ndarray) -> np.ndarray:
        return self.skill.velocity(parameters, tau)

    def window_poses(self, parameters: np.ndarray, indices: np.ndarray) -> np.ndarray:
        """The window's via-points themselves, (L, 6)."""
        window: np.ndarray = parameters[indices]
        return window


def variance_gate(promp: ObjectCentricProMP, centres: np.ndarray) -> np.ndarray:
    """Per residual basis centre, how much of the residual acts there, shape (N,), in [0, 1].

    Carvalho et al. use the demonstrations' variability "as a decision variable to reduce
    the search space for RRL": the residual acts where the ProMP's variance is low (where
    the demonstrations agree, the task needs precision, and a correction is what the
    nominal lacks) and is held back where it is high. Here, without a threshold to tune:
    ``1 - sigma(tau_j) / max_k sigma(tau_k)``, sigma the ProMP's positional standard
    deviation (the mean over x, y, z) at the basis centre, in the object frame. A ProMP with
    no variability (sigma = 0 everywhere) gates nothing.
    """
    sigma = promp.trajectory_std(np.clip(centres, 0.0, 1.0))[:, :3].mean(axis=1)
    top = float(sigma.max())
    if top <= 1e-12:
        return np.ones(len(centres))
    gate: np.ndarray = 1.0 - sigma / top
    return gate


class ResidualProMPTrajectory:
    """ProMP-RRL's trajectory: ``nominal(tau) + B(tau) @ Gamma``, Gamma the residual weights.

    The nominal is the object-centric ProMP's mean for the TC's object offset, conditioned
    to start at the start pose; B is the gated, normalised Gaussian basis centred at the
    via-point times (width = their spacing).

    Args:
        promp: the fitted object-centric ProMP.
        centres: the basis centres (N,), normalised times, evenly spaced.
        gate: the per-centre `variance_gate` (N,).
        duration: the trajectory's duration, s.
    """

    def __init__(
        self, promp: ObjectCentricProMP, centres: np.ndarray, gate: np.ndarray, duration: float
    ) -> None:
        self.promp = promp
        self.centres = np.asarray(centres, dtype=float)
        self.gate = np.asarray(gate, dtype=float)
        self.duration = float(duration)
        self._nominal_promp: ObjectCentricProMP | None = None
        self._object_offset = np.zeros(3)

    def basis(self, tau: np.ndarray) -> np.ndarray:
        """The gated, normalised residual basis B at ``tau`` (m,): (m, N)."""
        centres = self.centres
        width = centres[1] - centres[0]
        values = np.exp(-0.5 * ((np.asarray(tau)[:, None] - centres[None, :]) / width) ** 2)
        basis: np.ndarray = values / values.sum(axis=1, keepdims=True) * self.gate[None, :]
        return basis

    def nominal(self, tau: np.ndarray) -> np.ndarray:
        """The conditioned ProMP mean at ``tau`` (m,), (m, 6) (after `condition`)."""
        if self._nominal_promp is None:
            raise RuntimeError("condition() the residual trajectory on a TC first")
        return self._nominal_promp.mean_trajectory(np.clip(tau, 0.0, 1.0), self._object_offset)

    def parameter_map(self, tau: np.ndarray) -> np.ndarray:
        return self.basis(tau)

    def condition(self, tc: TaskConfigLike, start_pose: np.ndarray) -> np.ndarray:
        """Nominal: the ProMP mean for the TC's object offset, conditioned on the start pose
        (6,); returns zero residual weights (N, 6)."""
        self._object_offset = np.r_[np.asarray(tc.object_offset, dtype=float), 0.0]
        self._nominal_promp = self.promp.conditioned(
            0.0, start_pose, object_position=self._object_offset
        )
        return np.zeros((len(self.centres), 6))

    def offset(self, tau: np.ndarray, parameter_map: np.ndarray) -> np.ndarray:
        """The nominal at ``tau``, (m, 6)."""
        return self.nominal(tau)

    def position(self, parameters: np.ndarray, tau: np.ndarray) -> np.ndarray:
        poses: np.ndarray = self.nominal(tau) + self.basis(tau) @ parameters
        return poses

    def velocity(self, parameters: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Finite-difference velocity of the planned poses on 400 points, interpolated."""
        dense = np.linspace(0.0, 1.0, 400)
        velocity = np.gradient(self.position(parameters, dense), dense * self.duration, axis=0)
        return np.stack([np.interp(tau, dense, velocity[:, a]) for a in range(6)], axis=1)

    def window_poses(self, parameters: np.ndarray, indices: np.ndarray) -> np.ndarray:
        """The planned poses at the window's basis centres, (L, 6)."""
        return self.position(parameters, self.centres[indices])
