"""Which run folders the tables, paired analyses and curves may use.

A run counts when it has the result file a report reads — ``summary.json`` (evaluated) for the
tables, ``done.json`` (trained) for the learning curves — and the config hash recorded there is
the one the code resolves for it now; a run of an older configuration is left out and listed
(`distgprl status`: "stale"). A damaged run (`distgprl.runstate` verdict ``damaged``) is an
error naming the file and the reason (:class:`~distgprl.runstate.DamagedRunError`, exit 2 at
the CLI), never quietly left out.

**Which evaluation** (`run_evaluations`): a trained run has its final policy's
(``evaluation.csv`` / ``summary.json``) and its best learning-curve policy's
(``evaluation_best.csv`` / ``summary_best.json``); an untrained reference (`demo`,
`promp-nominal`) has one, used for both. The tables report :data:`TABLE_POLICY`.

**Which methods**: every method's runs under the preset, except the study methods reported
beside Table I (`distgprl.methods.STUDY_METHODS`: their runs share the preset's folder), which a
report reads only by asking for them (``methods``).
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from distgprl.errors import UserInputError
from distgprl.methods import METHODS, REPORTED_METHODS
from distgprl.runstate import run_state
from distgprl.schema import POLICY_CHOICES, evaluation_file_names, read_json

TABLE_POLICY = "best"
"""The policy whose evaluation Table I (``table1_<preset>``), the per-run table, the aggregates
and the claims report: the best learning-curve policy, Algorithm 1's output (protocol v6,
rule 6, docs/findings/protocol.md); the final policy's Table I (``table1_final_<preset>``) is
written beside it."""

UNTRAINED = "untrained"
"""`RunEvaluation.policy` of an untrained reference: its only evaluation, in both tables."""


@dataclass(frozen=True)
class RunSelection:
    """Run folders (``<root>/<preset>/<task>/<method>/seed<k>``) that count, and why others
    do not.

    Attributes:
        current: the runs (with the marker file) of the current configuration.
        excluded: one line per left-out run: its ``task/method/seed<k>`` and the reason.
        checked: False if the preset is not one of this checkout's (``experiments/``), so
            the config hashes could not be checked (only "finished" was).
    """

    current: frozenset[Path]
    excluded: tuple[str, ...]
    checked: bool

    def note(self) -> str:
        """A sentence for the tables: what was left out (empty if nothing)."""
        parts = []
        if self.excluded:
            parts.append(f"Not tabulated ({len(self.excluded)}): " + "; ".join(self.excluded))
        if not self.checked:
            parts.append("Config hashes not checked: the preset is not in experiments/")
        return ". ".join(parts)


def run_keys(folder: Path) -> tuple[str, str, int]:
    """(task, method, seed) of a run folder ``<root>/<preset>/<task>/<method>/seed<k>``."""
    return folder.parent.parent.name, folder.parent.name, int(folder.name.removeprefix("seed"))


def _config_hash(path: Path) -> Any:
    """The config hash a result file records (None if it records none)."""
    return read_json(path)["meta"].get("config_hash")


@cache
def known_preset(preset: str) -> bool:
    """Whether ``preset`` is one of this checkout's (so its runs' hashes can be resolved)."""
    from distgprl.config import load_config

    try:
        load_config(preset)
    except UserInputError:
        return False
    return True


@cache
def current_hash(task: str, method: str, seed: int, preset: str) -> str:
    """The config hash the code resolves for a run (fixed while the process runs; the reports
    ask for the same runs once per table, figure and method)."""
    from distgprl.identity import resolve_run

    return resolve_run(task, method, seed, preset).hash


def select_runs(
    root: str | Path,
    preset: str,
    marker: str = "summary.json",
    seeds: Collection[int] | None = None,
    methods: Collection[str] | None = None,
) -> RunSelection:
    """The run folders under ``<root>/<preset>`` holding ``marker`` (``summary.json`` or
    ``done.json``; the untrained `demo` reference always by its ``summary.json``) of the
    current configuration (module docstring); with ``seeds``, a trained method's runs of
    those seeds only (a study compares its readings at its own seeds,
    `distgprl.studies.Study.seeds`; an untrained reference, run once at seed 0, stays); with
    ``methods``, those methods' runs only (default: `REPORTED_METHODS`)."""
    checked = known_preset(preset)
    current, excluded = set(), []
    wanted = set(REPORTED_METHODS if methods is None else methods)
    for folder in sorted((Path(root) / preset).glob("*/*/seed*")):
        if not folder.is_dir() or folder.parent.name not in wanted & set(METHODS):
            continue
        task, method, seed = run_keys(folder)
        trainable = METHODS[method].trainable
        if seeds is not None and trainable and seed not in seeds:
            continue
        hash_now = current_hash(task, method, seed, preset) if checked else None
        # A damaged run stops the report, never a run silently left out (exit 2).
        state = run_state(folder, trainable, hash_now)
        if state.verdict == "damaged":
            raise state.error()
        path = folder / (marker if trainable else "summary.json")
        if not path.exists():
            continue
        if checked and _config_hash(path) != hash_now:
            stale = "configuration changed since; `distgprl status`: stale"
            excluded.append(f"{'/'.join(folder.parts[-3:])} ({stale})")
            continue
        current.add(folder)
    return RunSelection(frozenset(current), tuple(excluded), checked)


@dataclass(frozen=True)
class RunEvaluation:
    """One run's evaluation a table reports.

    Attributes:
        folder: the run folder (``<root>/<preset>/<task>/<method>/seed<k>``).
        policy: the policy evaluated: ``"best"``, ``"final"`` or :data:`UNTRAINED`.
        summary: its summary file (``summary[_best].json``).
        episodes: its per-episode rows (``evaluation[_best].csv``; may be absent).
    """

    folder: Path
    policy: str
    summary: Path
    episodes: Path

    @property
    def keys(self) -> dict[str, Any]:
        """The evaluation's ``task``, ``method``, ``seed`` (`run_keys`) and ``policy``."""
        task, method, seed = run_keys(self.folder)
        return {"task": task, "method": method, "seed": seed, "policy": self.policy}


@dataclass(frozen=True)
class EvaluationSelection:
    """The evaluations of the runs that count (`run_evaluations`) and what stands in.

    Attributes:
        evaluations: one per run that counts, sorted by folder.
        substituted: one line per trained run shown with its final policy because its best
            policy has no evaluation of the run's configuration (``policy="best"`` only).
        runs: the `select_runs` selection they come from.
    """

    evaluations: tuple[RunEvaluation, ...]
    substituted: tuple[str, ...]
    runs: RunSelection

    def note(self) -> str:
        """`RunSelection.note` and the substituted runs (empty if neither)."""
        parts = [self.runs.note()]
        if self.substituted:
            parts.append(
                f"Final policy in place of the best ({len(self.substituted)}; no best-policy "
                "evaluation, `distgprl evaluate --policy best`): " + "; ".join(self.substituted)
            )
        return ". ".join(part for part in parts if part)


def run_evaluations(
    root: str | Path,
    preset: str,
    policy: str = TABLE_POLICY,
    seeds: Collection[int] | None = None,
    methods: Collection[str] | None = None,
) -> EvaluationSelection:
    """The evaluation of ``policy`` (``"best"`` or ``"final"``) of each run that counts
    (`select_runs`: evaluated, current configuration). An untrained reference has only one
    evaluation, used for either policy. A trained run whose best policy has no evaluation, or
    one recorded under another config hash than its final evaluation's, is shown with its
    final policy and listed (`EvaluationSelection.substituted`), never left out silently.
    ``seeds``: as `select_runs`."""
    if policy not in POLICY_CHOICES:
        raise UserInputError(f"unknown policy {policy!r}; choose from {', '.join(POLICY_CHOICES)}")
    runs = select_runs(root, preset, seeds=seeds, methods=methods)
    final_csv, final_summary = evaluation_file_names(None, "final")
    best_csv, best_summary = evaluation_file_names(None, "best")
    evaluations, substituted = [], []
    for folder in sorted(runs.current):
        final = RunEvaluation(folder, "final", folder / final_summary, folder / final_csv)
        best = RunEvaluation(folder, "best", folder / best_summary, folder / best_csv)
        if not METHODS[folder.parent.name].trainable:
            evaluations.append(RunEvaluation(folder, UNTRAINED, final.summary, final.episodes))
        elif policy == "final":
            evaluations.append(final)
        elif best.summary.exists() and _config_hash(best.summary) == _config_hash(final.summary):
            evaluations.append(best)
        else:
            evaluations.append(final)
            substituted.append("/".join(folder.parts[-3:]))
    return EvaluationSelection(tuple(evaluations), tuple(substituted), runs)
