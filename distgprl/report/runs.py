"""Which run folders the reports may use.

A run counts when it has the file a report reads (``summary.json`` for the tables,
``done.json`` for the learning curves) recorded under the config hash the code resolves for it
now; an older configuration's run is left out and listed ("stale"), a damaged one is an error
(:class:`~distgprl.runstate.DamagedRunError`, exit 2). Study methods
(`distgprl.methods.STUDY_METHODS`) are read only when asked for.
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
"""The policy the tables report: the best trained learning-curve policy, Algorithm 1's output
(docs/findings/protocol.md, rule 6; never the untrained step-0 actor: protocol rule 2)."""

UNTRAINED = "untrained"
"""`RunEvaluation.policy` of an untrained reference (one evaluation, used for both)."""


@dataclass(frozen=True)
class RunSelection:
    """Run folders (``<root>/<preset>/<task>/<method>/seed<k>``) that count (``current``),
    one line per run left out (``excluded``), and whether the config hashes could be checked
    (``checked``: False for a preset not in ``experiments/``)."""

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
    return read_json(path)["meta"].get("config_hash")


@cache
def known_preset(preset: str) -> bool:
    """Whether ``preset`` is one of this checkout's."""
    from distgprl.config import load_config

    try:
        load_config(preset)
    except UserInputError:
        return False
    return True


@cache
def current_hash(task: str, method: str, seed: int, preset: str) -> str:
    """The config hash the code resolves for a run (cached: fixed while the process runs)."""
    from distgprl.identity import resolve_run

    return resolve_run(task, method, seed, preset).hash


def select_runs(
    root: str | Path,
    preset: str,
    marker: str = "summary.json",
    seeds: Collection[int] | None = None,
    methods: Collection[str] | None = None,
) -> RunSelection:
    """The current-configuration run folders under ``<root>/<preset>`` holding ``marker``
    (an untrained reference: its ``summary.json``); ``seeds`` limits trained methods' runs,
    ``methods`` the methods (default `REPORTED_METHODS`)."""
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
    """One run's evaluation of ``policy`` (``best``, ``final`` or `UNTRAINED`): its
    ``summary[_best].json`` and per-episode ``evaluation[_best].csv`` (may be absent)."""

    folder: Path
    policy: str
    summary: Path
    episodes: Path

    @property
    def keys(self) -> dict[str, Any]:
        """``task``, ``method``, ``seed`` and ``policy``."""
        task, method, seed = run_keys(self.folder)
        return {"task": task, "method": method, "seed": seed, "policy": self.policy}


@dataclass(frozen=True)
class EvaluationSelection:
    """One evaluation per run that counts, by folder; ``substituted``: the trained runs
    shown with their final policy for want of a best-policy evaluation; ``runs``: the
    `select_runs` selection."""

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
    """The ``policy`` (``best`` or ``final``) evaluation of each run `select_runs` counts. A
    trained run without a best-policy evaluation of its final one's config hash is shown with
    its final policy and listed in ``substituted``."""
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
