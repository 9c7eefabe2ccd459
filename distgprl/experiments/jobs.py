"""`Job`: one (task, method, seed) of a sweep, the unit `distgprl.experiments.sweep` runs.

Its own module so that what a sweep does with a job (`distgprl.experiments.follow_ups`, the
`distgprl.experiments.status` of its run) imports it from below the sweep instead of from
the sweep itself.
"""

from __future__ import annotations

from dataclasses import dataclass

from distgprl.trial_protocol import TABLE2_POLICY


@dataclass(frozen=True)
class Job:
    """One (task, method, seed) of a sweep."""

    task: str
    method: str
    seed: int
    preset: str
    root: str
    twin_trials: int = 0  # trials per Table II setting after a DBM job (0: none)
    repair_evaluations: bool = False  # safety-layer evaluations after the run
    named_with_preset: bool = False  # a study's job: its name says which preset (reading)
    trial_policy: str = TABLE2_POLICY  # the trained policy its twin trials run

    @property
    def name(self) -> str:
        run = f"{self.task}/{self.method}/seed{self.seed}"
        return f"{self.preset}/{run}" if self.named_with_preset else run
