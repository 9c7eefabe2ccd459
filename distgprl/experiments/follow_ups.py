"""What a sweep does for a finished run while its model is still on disk ("follow-ups").

A trained policy's weights are not committed, so whatever needs the policy beyond its plain
evaluation has to run where it was trained: the Table II digital-twin trials of a DBM policy
(`distgprl.experiments.table2_trials`, ``Job.twin_trials``: the paper's protocol first, then the
safety layer's settings beside it, `distgprl.trial_protocol`) and the evaluations with the
hardware safety layer in the loop of every run (`distgprl.experiments.repair_follow_ups`,
``Job.repair_evaluations``). `distgprl.experiments.sweep` runs them right after training, and
picks a finished run up again for them alone when they are due. Each report is a
`JobResult` field (``trials``, ``repairs``); a follow-up failure never fails its job.
"""

from __future__ import annotations

from typing import TypedDict

from distgprl.experiments.jobs import Job
from distgprl.methods import get_method, has_via_point_plan


class FollowUpReports(TypedDict):
    """What `run_follow_ups` did, as the `JobResult` fields of the same names (empty: none
    was due)."""

    trials: str
    repairs: str


def follow_up_due(job: Job) -> bool:
    """True if a finished run still needs what the sweep does after training while its
    model is on disk: Table II twin trials (`trials_due`) or safety-layer evaluations
    (`repairs_due`)."""
    return trials_due(job) or repairs_due(job)


def run_follow_ups(job: Job) -> FollowUpReports:
    """Run the job's due follow-ups; their reports as `JobResult` fields."""
    return {
        "trials": run_job_trials(job) if trials_due(job) else "",
        "repairs": run_job_repairs(job) if repairs_due(job) else "",
    }


def repairs_due(job: Job) -> bool:
    """True if the job should evaluate its run with the safety layer now
    (`repair_follow_ups.evaluations_due`)."""
    if not job.repair_evaluations or not has_via_point_plan(get_method(job.method)):
        return False  # methods.NO_SAFETY_LAYER: not implemented for residual-control methods
    from distgprl.experiments.repair_follow_ups import evaluations_due

    return evaluations_due(job.root, job.preset, job.task, job.method, job.seed)


def run_job_repairs(job: Job) -> str:
    """Run the job's missing safety-layer evaluations: a report
    (`repair_follow_ups.run_and_report`)."""
    from distgprl.experiments.repair_follow_ups import run_and_report

    return run_and_report(job.root, job.preset, job.task, job.method, job.seed)


def trials_due(job: Job) -> bool:
    """True if the job should run Table II twin trials now (`table2_trials.trials_due`)."""
    if job.twin_trials <= 0 or job.task != "dbm":
        return False
    from distgprl.experiments.table2_trials import trials_due as due

    return due(job.method, job.seed, job.preset, job.root, job.twin_trials, job.trial_policy)


def run_job_trials(job: Job) -> str:
    """Run the job's missing Table II twin trials (the paper's protocol and the safety
    layer's settings, `table2_trials.table2_settings`): a report
    (`table2_trials.run_and_report`)."""
    from distgprl.experiments.table2_trials import run_and_report

    return run_and_report(
        job.method, job.seed, job.preset, job.root, job.twin_trials, job.trial_policy
    )
