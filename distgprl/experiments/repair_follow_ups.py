"""The safety-layer evaluations a sweep runs for each finished run ("Table I + repair").

A trained policy's weights are not committed, so what the hardware safety layer costs and
saves in simulation (`distgprl.experiments.safety_layer_evaluation`) has to be measured where
the policy was trained, while its ``model.zip`` is on disk, as the Table II twin trials are
(`distgprl.experiments.table2_trials`). `distgprl sweep` (``--repair-evaluations``, on by
default) evaluates every finished run of either task on the preset's evaluation TCs in the
two modes of :data:`SWEEP_REPAIR_MODES`:

- ``check``: the layer refuses every unsafe window at once (no retiming, no push): what
  the pre-flight check alone saves and costs;
- ``repair``: the layer re-times a plan that is too fast and refuses what is still unsafe
  (``distgprl evaluate --plan-repair``, the default of the hardware trials' ``safety-layer``
  protocol).

The via-point push (``--repair-push``) is left out, as it is off by default on hardware
(docs/FINDINGS.md "Hardware plan repair and camera noise"). An evaluation counts as done
when its summary exists and records the run's current config hash.
`distgprl.report.repair` tabulates them beside the plain evaluation.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from distgprl.identity import resolve_run
from distgprl.methods import get_method, has_via_point_plan
from distgprl.safety_layer.retime import RepairConfig
from distgprl.schema import read_json, repair_evaluation_file_names, run_dir

SWEEP_REPAIR_MODES = ("check", "repair")
"""Modes (:data:`~distgprl.schema.REPAIR_MODES`) a sweep evaluates each run in."""


def mode_config(mode: str) -> RepairConfig:
    """The :class:`RepairConfig` of a sweep mode (module docstring)."""
    if mode == "check":
        return RepairConfig(retime=False, repair=False)
    if mode == "repair":
        return RepairConfig(retime=True, repair=False)
    raise ValueError(f"not a sweep repair mode: {mode!r} (one of {SWEEP_REPAIR_MODES})")


def missing_modes(
    root: str | Path, preset: str, task: str, method: str, seed: int
) -> tuple[str, ...]:
    """The modes of :data:`SWEEP_REPAIR_MODES` without a summary of the run's current
    configuration in its folder."""
    folder = run_dir(root, preset, task, method, seed)
    current = resolve_run(task, method, seed, preset).hash
    missing = []
    for mode in SWEEP_REPAIR_MODES:
        path = folder / repair_evaluation_file_names(None, "final", mode)[1]
        if not path.exists() or read_json(path).get("meta", {}).get("config_hash") != current:
            missing.append(mode)
    return tuple(missing)


def evaluations_due(root: str | Path, preset: str, task: str, method: str, seed: int) -> bool:
    """True if the run is finished (its plain ``summary.json`` exists), its policy can be
    loaded (a trained method's ``model.zip`` is on disk; a reference needs none) and a mode
    is missing."""
    folder = run_dir(root, preset, task, method, seed)
    if not (folder / "summary.json").exists():
        return False
    if get_method(method).trainable and not (folder / "model.zip").exists():
        return False
    return bool(missing_modes(root, preset, task, method, seed))


def run_and_report(root: str | Path, preset: str, task: str, method: str, seed: int) -> str:
    """Evaluate the run in every missing mode; a report line for a sweep's log. A failure
    never raises here (the run it follows is done; the next sweep tries again)."""
    from distgprl.experiments.safety_layer_evaluation import evaluate_with_repair

    lines = []
    try:
        for mode in missing_modes(root, preset, task, method, seed):
            summary = evaluate_with_repair(
                task,
                method,
                seed,
                preset,
                root=root,
                config=mode_config(mode),
                show_progress=False,
            )
            lines.append(
                f"safety layer ({mode}): success {summary['success_rate']:.2f}, collision "
                f"{summary['collision_rate']:.2f}, refused {summary['refused_rate']:.2f}"
            )
    except Exception as exc:  # reported with the job
        lines.append(f"safety-layer evaluation failed: {type(exc).__name__}: {exc}")
    return "\n  ".join(lines)


@dataclass(frozen=True)
class RepairCoverage:
    """How far a sweep's finished runs have their safety-layer evaluations.

    Attributes:
        complete: runs (task/method/seed) with both modes of their configuration.
        pending: runs lacking a mode whose policy is on disk (the next sweep runs it).
        lost: trained runs lacking a mode whose ``model.zip`` is gone (a run committed
            from another machine, or trained before the sweep made these evaluations).
        not_applicable: runs of methods without a window plan (`has_via_point_plan`:
            ProMP-RRL and its nominal), which the simulated safety layer does not evaluate
            and a sweep never schedules.
    """

    complete: tuple[str, ...]
    pending: tuple[str, ...]
    lost: tuple[str, ...]
    not_applicable: tuple[str, ...] = ()

    def describe(self) -> str:
        text = (
            f"Table I + repair evaluations: {len(self.complete)} runs complete, "
            f"{len(self.pending)} pending, {len(self.lost)} without their model on disk"
        )
        if self.not_applicable:
            text += f", {len(self.not_applicable)} without a window plan (not evaluated)"
        return text


def coverage(root: str | Path, preset: str, finished: list[tuple[str, str, int]]) -> RepairCoverage:
    """`RepairCoverage` of the finished runs ``finished`` ((task, method, seed) triples)."""
    complete, pending, lost, not_applicable = [], [], [], []
    for task, method, seed in finished:
        name = f"{task}/{method}/seed{seed}"
        if not has_via_point_plan(get_method(method)):
            not_applicable.append(name)
        elif not missing_modes(root, preset, task, method, seed):
            complete.append(name)
        elif evaluations_due(root, preset, task, method, seed):
            pending.append(name)
        else:
            lost.append(name)
    return RepairCoverage(tuple(complete), tuple(pending), tuple(lost), tuple(not_applicable))
