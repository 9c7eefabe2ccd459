"""The digital-twin trials Table II counts for one DBM policy, each setting run once.

Table II has, for every method's policies and every seed where one exists, twin trials
under the paper's protocol (the policy's trajectory executes, only the UR5e's own limits
apply, `distgprl.trial_protocol`) and, beside them, behind the safety layer with plan
repair on and off, and for every method a robustness series over the twin's sensor-noise
levels (safety layer, repair on). A policy's weights are not kept
with the committed results (only a run's small files are), so its trials have to be run
where and when it was trained: `distgprl sweep --twin-trials N` runs the missing settings
of every DBM run it finishes (or finds finished with its ``model.zip`` still on disk) in
the same job, and a later sweep fills in what an interrupted one left.

A setting counts as done when a trial file of it exists that Table II would count: the
twin backend, this preset, its protocol (a file without one ran behind the safety layer),
neither ``--force`` nor a dry run, pushes off, at least the requested number of trials, and
(trained methods) the policy's current config hash.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from distgprl.hardware.trial_rows import describe_summary
from distgprl.identity import resolve_run
from distgprl.methods import TABLE_ORDER, get_method
from distgprl.schema import read_csv, run_dir, trial_file_exclusion
from distgprl.trial_protocol import (
    FINAL_POLICY,
    PAPER,
    SAFETY_LAYER,
    TABLE2_POLICY,
    check_trial_policy,
    file_protocol,
)

__all__ = [
    "PAPER_SETTING",
    "ROBUSTNESS_METHODS",
    "TABLE2_TRIALS",
    "TrialCoverage",
    "TrialSetting",
    "coverage",
    "missing_settings",
    "run_and_report",
    "run_table2_trials",
    "table2_settings",
    "trials_due",
]

HARDWARE_TASK = "dbm"
"""The task of the hardware cell (the policies its trials run are trained on it)."""

TABLE2_TRIALS = 10
"""Trials per setting (the paper's 10 hardware trials per method)."""

ROBUSTNESS_METHODS = TABLE_ORDER
"""Methods whose trials also run at every sensor-noise level (the robustness table and its
curve): every method of Table I and its references (issue 50 item 5: where does each policy
break?); ProMP-RRL's residual RL one 0.1 s step at a time
(`distgprl.hardware.adapter.TrialAdapter`'s ``RL step`` decisions)."""

NOISE_LEVELS = (1, 2, 3, 4)
"""The twin's sensor-noise levels above none (`distgprl.hardware.twin.SENSOR_NOISE`)."""


@dataclass(frozen=True)
class TrialSetting:
    """How one trial file's trials run: the protocol (`distgprl.trial_protocol`), plan
    repair (retiming; the safety layer's, always off under the paper's protocol) on or off,
    twin noise level."""

    repair: bool
    sensor_noise: int
    protocol: str = SAFETY_LAYER

    def describe(self) -> str:
        if self.protocol == PAPER:
            return f"paper's protocol, noise {self.sensor_noise}"
        return f"safety layer, repair {'on' if self.repair else 'off'}, noise {self.sensor_noise}"


PAPER_SETTING = TrialSetting(False, 0, PAPER)
"""Table II's primary setting: the paper's protocol on the noiseless twin."""


def table2_settings(method: str, policy: str = TABLE2_POLICY) -> tuple[TrialSetting, ...]:
    """The settings Table II wants for ``method``: the paper's protocol (`PAPER_SETTING`)
    first, then the safety layer with repair on and off without sensor noise, and
    (`ROBUSTNESS_METHODS`) the safety layer with repair on at every noise level. Of another
    ``policy`` than Table II's (`distgprl.trial_protocol.TRIAL_POLICIES`; its table beside
    Table II) the first three: Table II's table, not its noise curve."""
    settings = [PAPER_SETTING, TrialSetting(True, 0), TrialSetting(False, 0)]
    if method in ROBUSTNESS_METHODS and check_trial_policy(policy) == TABLE2_POLICY:
        settings += [TrialSetting(True, level) for level in NOISE_LEVELS]
    return tuple(settings)


def model_path(root: str | Path, preset: str, method: str, seed: int) -> Path:
    """Where the trained DBM run keeps its final policy (`distgprl.experiments.training`)."""
    return run_dir(root, preset, HARDWARE_TASK, method, seed) / "model.zip"


def _done_settings(
    root: str | Path, preset: str, method: str, seed: int, trials: int, policy: str
) -> set[TrialSetting]:
    """Settings with a trial file of ``policy`` Table II (or its table of ``policy``) counts
    (module docstring)."""
    folder = Path(root) / "hardware" / method
    trainable = get_method(method).trainable
    current = resolve_run(HARDWARE_TASK, method, seed, preset).hash if trainable else None
    done = set()
    for path in sorted(folder.glob(f"trials_twin_seed{seed}_*.csv")) if folder.exists() else []:
        meta, rows = read_csv(path)
        if (
            meta.get("preset") != preset
            or meta.get("backend") != "twin"
            or meta.get("repair_push")
            or len(rows) < trials
            or trial_file_exclusion(meta, current, policy)
        ):
            continue
        protocol = file_protocol(meta)
        repair = bool(meta.get("repair")) and protocol != PAPER
        done.add(TrialSetting(repair, int(meta.get("sensor_noise") or 0), protocol))
    return done


def missing_settings(
    root: str | Path,
    preset: str,
    method: str,
    seed: int,
    trials: int = TABLE2_TRIALS,
    policy: str = TABLE2_POLICY,
) -> tuple[TrialSetting, ...]:
    """The settings of `table2_settings` without a counted trial file of ``trials`` trials
    of ``policy`` (a reference's files, which run no policy, count for every one)."""
    done = _done_settings(root, preset, method, seed, trials, policy)
    return tuple(s for s in table2_settings(method, policy) if s not in done)


def policy_on_disk(root: str | Path, preset: str, method: str, seed: int, policy: str) -> bool:
    """True if the DBM run's ``policy`` can run here: a reference (no policy), the final
    policy's ``model.zip``, or the best policy the run ships (or keeps beside its model)."""
    from distgprl.experiments.policies import SHIPPED_POLICY

    if not get_method(method).trainable:
        return True
    final = model_path(root, preset, method, seed)
    return final.exists() or (policy != FINAL_POLICY and (final.parent / SHIPPED_POLICY).exists())


def run_table2_trials(
    method: str,
    seed: int,
    preset: str,
    root: str | Path = "results",
    trials: int = TABLE2_TRIALS,
    echo: Callable[[str], None] = print,
    policy: str = TABLE2_POLICY,
) -> list[Path]:
    """Run the twin trials of every missing setting of the DBM policy (method, seed, preset)
    that ``policy`` names (`distgprl.trial_protocol.TRIAL_POLICIES`).

    Returns the trial files written (none if every setting is done).

    Raises:
        UserInputError: a trained method's DBM model is not on disk (``model.zip``, nor the
            shipped best actor).
    """
    from distgprl.experiments.trial_policy import load_trial_policy
    from distgprl.hardware.trials import run_trials
    from distgprl.safety_layer.retime import RepairConfig

    written = []
    load_policy = partial(load_trial_policy, policy=policy)
    for setting in missing_settings(root, preset, method, seed, trials, policy):
        report = run_trials(
            trials=trials,
            method=method,
            seed=seed,
            backend="twin",
            root=root,
            preset=preset,
            repair=setting.repair,
            repair_config=RepairConfig(repair=False),
            sensor_noise=setting.sensor_noise,
            protocol=setting.protocol,
            echo=lambda line: None,
            load_policy=load_policy,
        )
        echo(
            f"twin trials {method} seed {seed} ({setting.describe()}, {policy} policy): "
            f"{describe_summary(report.summary, setting.protocol)} -> {report.path}"
        )
        written.append(report.path)
    return written


def trials_due(
    method: str,
    seed: int,
    preset: str,
    root: str | Path,
    trials: int,
    policy: str = TABLE2_POLICY,
) -> bool:
    """True if the DBM policy's trials can and should run now: ``policy`` is on disk
    (`policy_on_disk`) and a setting is still without ``trials`` counted trials of it."""
    if not policy_on_disk(root, preset, method, seed, policy):
        return False
    return bool(missing_settings(root, preset, method, seed, trials, policy))


def run_and_report(
    method: str,
    seed: int,
    preset: str,
    root: str | Path,
    trials: int,
    policy: str = TABLE2_POLICY,
) -> str:
    """`run_table2_trials` as a report for a sweep's log: one line per setting run, or what
    failed (a trial failure never raises here: the run it follows is done, and the next
    sweep tries again)."""
    lines: list[str] = []
    try:
        written = run_table2_trials(
            method, seed, preset, root, trials, echo=lines.append, policy=policy
        )
    except Exception as exc:  # reported with the job
        return f"twin trials failed: {type(exc).__name__}: {exc}"
    return "\n  ".join([f"twin trials: {len(written)} setting(s) run", *lines])


@dataclass(frozen=True)
class TrialCoverage:
    """How far a sweep's DBM policies have their Table II twin trials.

    Attributes:
        complete: policies (method/seed) with a counted trial file of every setting.
        pending: finished policies still on disk that lack settings (the next sweep runs
            them).
        lost: finished trained policies lacking settings whose ``model.zip`` is gone (their
            trials can no longer run: a run committed from another machine).
    """

    complete: tuple[str, ...]
    pending: tuple[str, ...]
    lost: tuple[str, ...]

    def describe(self) -> str:
        text = (
            f"Table II twin trials: {len(self.complete)} DBM policies complete, "
            f"{len(self.pending)} pending"
        )
        if self.lost:
            text += f", {len(self.lost)} without their model on disk ({', '.join(self.lost)})"
        return text


def coverage(
    root: str | Path,
    preset: str,
    finished: list[tuple[str, int]],
    trials: int = TABLE2_TRIALS,
) -> TrialCoverage:
    """`TrialCoverage` of the finished DBM runs ``finished`` ((method, seed) pairs)."""
    complete, pending, lost = [], [], []
    for method, seed in finished:
        name = f"{method}/seed{seed}"
        if not missing_settings(root, preset, method, seed, trials):
            complete.append(name)
        elif get_method(method).trainable and not model_path(root, preset, method, seed).exists():
            lost.append(name)
        else:
            pending.append(name)
    return TrialCoverage(tuple(complete), tuple(pending), tuple(lost))
