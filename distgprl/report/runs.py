"""Which run folders the tables, paired analyses and curves may use.

A run counts when it has the result file a report reads — ``summary.json`` (evaluated) for the
tables and paired analyses, ``done.json`` (trained) for the learning curves — and the config
hash recorded there is the one the code resolves for it now: a run of an older configuration
(say, before a fix to a part of the method, which changes the hash of the methods using it)
is left out, and listed, instead of being averaged with the current ones. `distgprl status`
calls such runs "stale". A damaged run (the `distgprl.runstate` verdict
``damaged``: a result file of an unknown schema version or not a result at all, or the
evaluation of a finished run gone) is an error naming the file and the reason
(:class:`~distgprl.runstate.DamagedRunError`, exit 2 at the CLI), in the tables
and the curves alike, never a run quietly left out.

So a report is a function of the result files and, for this checkout's presets, of the
configuration the code resolves for them (presets and method revisions): a change to a
preset or to a part of the method changes which runs count, not their figures.

**Which evaluation** (`run_evaluations`): a trained run has two, its final policy's
(``evaluation.csv`` / ``summary.json``) and its best learning-curve policy's
(``evaluation_best.csv`` / ``summary_best.json``); an untrained reference (`demo`,
`promp-nominal`) has one, used for both. Table I, its per-run table, the aggregates and the
claims report :data:`TABLE_POLICY`, the best policy: Algorithm 1's output
(docs/findings/protocol.md, rule 6); the final policy's Table I is written beside it.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from distgprl.errors import UserInputError
from distgprl.methods import METHODS
from distgprl.runstate import run_state
from distgprl.schema import POLICY_CHOICES, evaluation_file_names, read_json

TABLE_POLICY = "best"
"""The policy whose evaluation Table I (``table1_<preset>``) reports, and with it the per-run
table, the aggregates and the claims (`distgprl.report.table1.collect_scores`): the best
learning-curve policy, Algorithm 1's output ("query GP updated by best policy";
docs/findings/protocol.md, rule 6). The one switch between the two evaluations: the final policy's
Table I (``table1_final_<preset>``) is written beside it."""

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
) -> RunSelection:
    """The run folders under ``<root>/<preset>`` holding ``marker`` (``summary.json`` or
    ``done.json``; the untrained `demo` reference always by its ``summary.json``) of the
    current configuration (module docstring); with ``seeds``, a trained method's runs of
    those seeds only (a study compares its readings at its own seeds,
    `distgprl.studies.Study.seeds`; an untrained reference, run once at seed 0, stays)."""
    base = Path(root) / preset
    folders = sorted(
        p
        for p in base.glob("*/*/seed*")
        if p.is_dir()
        and (
            seeds is None
            or p.parent.name not in METHODS
            or not METHODS[p.parent.name].trainable
            or int(p.name.removeprefix("seed")) in seeds
        )
    )
    checked = known_preset(preset)
    current, excluded = set(), []
    for folder in folders:
        task, method = folder.parent.parent.name, folder.parent.name
        if method not in METHODS:
            continue
        name = f"{task}/{method}/{folder.name}"
        trainable = METHODS[method].trainable
        hash_now = None
        if checked:
            hash_now = current_hash(task, method, int(folder.name.removeprefix("seed")), preset)
        # A damaged run stops the report, never a run silently left out (exit 2).
        state = run_state(folder, trainable, hash_now)
        if state.verdict == "damaged":
            raise state.error()
        path = folder / (marker if trainable else "summary.json")
        if not path.exists():
            continue
        recorded = read_json(path)["meta"].get("config_hash")
        if checked:
            if recorded != hash_now:
                excluded.append(f"{name} (configuration changed since; `distgprl status`: stale)")
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
    def task(self) -> str:
        return self.folder.parent.parent.name

    @property
    def method(self) -> str:
        return self.folder.parent.name

    @property
    def seed(self) -> int:
        return int(self.folder.name.removeprefix("seed"))


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
        parts = [self.runs.note()] if self.runs.note() else []
        if self.substituted:
            parts.append(
                f"Final policy in place of the best ({len(self.substituted)}; no best-policy "
                "evaluation, `distgprl evaluate --policy best`): " + "; ".join(self.substituted)
            )
        return ". ".join(parts)


def run_evaluations(
    root: str | Path,
    preset: str,
    policy: str = TABLE_POLICY,
    seeds: Collection[int] | None = None,
) -> EvaluationSelection:
    """The evaluation of ``policy`` (``"best"`` or ``"final"``) of each run that counts
    (`select_runs`: evaluated, current configuration). An untrained reference has only one
    evaluation, used for either policy. A trained run whose best policy has no evaluation, or
    one recorded under another config hash than its final evaluation's, is shown with its
    final policy and listed (`EvaluationSelection.substituted`), never left out silently.
    ``seeds``: as `select_runs`."""
    if policy not in POLICY_CHOICES:
        raise UserInputError(f"unknown policy {policy!r}; choose from {', '.join(POLICY_CHOICES)}")
    runs = select_runs(root, preset, seeds=seeds)
    final_csv, final_summary = evaluation_file_names(None, "final")
    best_csv, best_summary = evaluation_file_names(None, "best")
    evaluations, substituted = [], []
    for folder in sorted(runs.current):
        final = RunEvaluation(folder, "final", folder / final_summary, folder / final_csv)
        if not METHODS[folder.parent.name].trainable:
            evaluations.append(RunEvaluation(folder, UNTRAINED, final.summary, final.episodes))
        elif policy == "final":
            evaluations.append(final)
        elif _same_configuration(folder / best_summary, final.summary):
            evaluations.append(
                RunEvaluation(folder, "best", folder / best_summary, folder / best_csv)
            )
        else:
            evaluations.append(final)
            substituted.append(f"{final.task}/{final.method}/{folder.name}")
    return EvaluationSelection(tuple(evaluations), tuple(substituted), runs)


def _same_configuration(best: Path, final: Path) -> bool:
    """Whether the best-policy summary exists and records the final summary's config hash."""
    if not best.exists():
        return False
    recorded = read_json(best)["meta"].get("config_hash")
    return bool(recorded == read_json(final)["meta"].get("config_hash"))
