"""Evaluate a run on the evaluation TCs: its final or best policy (or the `demo`
reference), one row per episode in ``evaluation*.csv`` and the summary in
``summary*.json`` (`distgprl.schema.evaluation_file_names`)."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from distgprl.errors import UserInputError
from distgprl.experiments.factories import make_env
from distgprl.experiments.policies import load_trained_policy
from distgprl.experiments.rollout import deterministic_policy, evaluate_policy, summarise
from distgprl.identity import resolve_run
from distgprl.schema import EVALUATION_FIELDS, evaluation_file_names, run_dir, write_csv, write_json


def evaluate_run(
    task: str,
    method: str,
    seed: int = 0,
    preset: str = "paper",
    episodes: int | None = None,
    root: str | Path = "results",
    show_progress: bool = True,
    policy: str = "final",
) -> dict[str, Any]:
    """Evaluate a trained run (or the `demo` reference) on the evaluation TCs.

    Writes ``evaluation.csv`` and ``summary.json`` into the run folder; with ``episodes``
    other than the preset's, a supplementary evaluation under the names of
    `evaluation_file_names` instead (the first ``episodes`` TCs of the same stream, so the
    preset's TCs are a prefix); returns the summary. A trained run is evaluated under the
    configuration it was trained with (its ``total_steps`` included), which must still be
    what the code resolves: a model of an older configuration is refused.

    ``policy="best"`` evaluates, instead of the final policy, the best learning-curve policy
    (Algorithm 1's "best policy": `best_curve_row` of ``progress.csv``, its actor kept by
    training) and writes the ``_best`` files of `evaluation_file_names`; the summary records
    the selected step and its curve figures. Only trained runs have one.
    """
    run = resolve_run(task, method, seed, preset)
    episodes = episodes or run.config.run.eval_episodes
    supplementary = episodes != run.config.run.eval_episodes
    csv_name, summary_name = evaluation_file_names(episodes if supplementary else None, policy)
    folder = run_dir(root, preset, task, method, seed)
    if policy == "best" and not run.method.trainable:
        raise UserInputError(f"{method} is not trained: it has no learning curve to select from")
    env = make_env(run)
    actor = None
    selected: dict[str, Any] = {}
    if run.method.trainable:
        trained = load_trained_policy(run, folder, env, policy)
        run, selected = trained.run, trained.selected
        actor = deterministic_policy(trained.model)
    elif not supplementary or not (folder / "config.json").exists():
        # the reference's config is written with its preset evaluation; a supplementary
        # evaluation leaves an existing one untouched (its own files carry their meta)
        write_json(
            folder / "config.json",
            {"run": run.to_dict(), "config_hash": run.hash},
            kind="config",
            config_hash=run.hash,
            seed=seed,
        )
    tcs = env.spec_task.evaluation_tcs(episodes)
    start = time.perf_counter()
    rows = evaluate_policy(env, tcs, actor, progress=show_progress)
    wall = time.perf_counter() - start
    env.close()
    summary = {**summarise(rows), "evaluation_wall_time_s": wall, **selected}
    meta = {"config_hash": run.hash, "seed": seed, "task": task, "method": method, "preset": preset}
    write_csv(folder / csv_name, rows, EVALUATION_FIELDS, **meta)
    write_json(folder / summary_name, {"summary": summary}, kind="summary", **meta)
    return summary


def describe(summary: dict[str, Any]) -> str:
    """The whole summary as one JSON line (``distgprl evaluate --json``)."""
    return json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in summary.items()})


def _percent(value: float) -> str:
    return f"{100 * value:.0f} %"


def _millimetres(value: float) -> str:
    return f"{1000 * value:.1f} mm"


SUMMARY_ROWS: tuple[tuple[str, str, Any], ...] = (
    ("episodes", "episodes", str),
    ("success_rate", "success", _percent),
    ("collision_rate", "collision", _percent),
    ("safe_success_rate", "safe success (success without collision)", _percent),
    ("completion_rate", "completion", _percent),
    ("refused_rate", "refused by the safety layer", _percent),
    ("min_clearance_p5", "clearance, 5th percentile of episode minima", _millimetres),
    ("mean_return", "mean return", lambda value: f"{value:.2f}"),
    ("joint_speed_over_limit_rate", "episodes over a joint speed limit", _percent),
    ("policy_step", "best policy: learning-curve step", str),
)
"""The rows of `summary_table`: summary key, label, format (keys absent are left out)."""


def summary_table(summary: dict[str, Any], title: str) -> str:
    """A small table of an evaluation's headline figures, under ``title`` (`SUMMARY_ROWS`;
    every figure: `describe`)."""
    rows = [
        (label, form(summary[key]))
        for key, label, form in SUMMARY_ROWS
        if summary.get(key) is not None
    ]
    width = max(len(label) for label, _ in rows) if rows else 0
    return "\n".join([title, *(f"  {label:<{width}}  {value:>8}" for label, value in rows)])
