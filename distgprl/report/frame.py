"""The committed runs as tidy pandas frames, the input of every table, claim and figure:
`run_frame` (one row per run's evaluation), `episode_frame` (per run × evaluation episode) and
`curve_frame` (per run × learning-curve point). Which runs count: `distgprl.report.runs`;
``attrs["note"]`` says which did not.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from distgprl.methods import METHODS
from distgprl.report.runs import TABLE_POLICY, RunEvaluation, run_evaluations, run_keys, select_runs
from distgprl.schema import collision_free_min_clearance_p5, read_csv, read_json

RUN_KEYS = ("task", "method", "seed")
"""The columns naming a run in every frame."""

EVALUATION_KEYS = (*RUN_KEYS, "policy")
"""A run's columns and the policy evaluated (``best``, ``final`` or ``untrained``)."""

COLLISION_FREE_MINCL = "min_clearance_p5_collision_free"
"""MinCl (m), docs/findings/protocol.md, rule 5; None where every episode
collided; ``collision_free_episodes`` counts the episodes it is over."""

TRAINING_FIELDS = ("train_wall_time_s", "cpu_s_per_step")
"""``done.json``'s wall time (s) and process CPU time per RL step (s); None where absent."""

RUN_COLUMNS = (*EVALUATION_KEYS, "folder", "config_hash", "numerics", *TRAINING_FIELDS)
"""The columns `run_frame` always has, before the summaries' fields."""


def with_collision_free_clearance(summary: dict[str, Any], episodes: Path) -> dict[str, Any]:
    """``summary`` with `COLLISION_FREE_MINCL` and ``collision_free_episodes``, computed from
    the ``episodes`` rows where the summary lacks them (unchanged without such rows)."""
    if COLLISION_FREE_MINCL in summary or not episodes.exists():
        return summary
    rows = read_csv(episodes)[1]
    if not rows or not all({"collision", "min_clearance"} <= row.keys() for row in rows):
        return summary
    value, count = collision_free_min_clearance_p5(rows)
    return {**summary, COLLISION_FREE_MINCL: value, "collision_free_episodes": count}


def _run_record(evaluation: RunEvaluation) -> dict[str, Any]:
    """One `run_frame` row: keys, hashes, training fields, then the summary's fields."""
    document = read_json(evaluation.summary)
    summary = with_collision_free_clearance(document["summary"], evaluation.episodes)
    done_path = evaluation.folder / "done.json"
    done = read_json(done_path) if done_path.exists() else {}
    machine = (done.get("meta") or {}).get("machine") or {}
    record: dict[str, Any] = {
        **evaluation.keys,
        "folder": evaluation.folder,
        "config_hash": document["meta"].get("config_hash", ""),
        "numerics": machine.get("numerics", ""),
    }
    record.update({key: done.get(key) for key in TRAINING_FIELDS})
    record.update({k: v for k, v in summary.items() if k not in record})
    return record


def run_frame(
    root: str | Path,
    preset: str,
    policy: str = TABLE_POLICY,
    seeds: Collection[int] | None = None,
    methods: Collection[str] | None = None,
) -> pd.DataFrame:
    """One row per run that counts (`run_evaluations`), in folder order: `RUN_COLUMNS`
    (``numerics``: the training machine's fingerprint, "" if unrecorded), then every summary
    field (``object`` columns, None where a summary lacks it)."""
    selection = run_evaluations(root, preset, policy, seeds, methods)
    records = [_run_record(evaluation) for evaluation in selection.evaluations]
    columns = list(dict.fromkeys([*RUN_COLUMNS, *(key for record in records for key in record)]))
    filled = [{column: record.get(column) for column in columns} for record in records]
    frame = pd.DataFrame(filled, columns=columns, dtype=object)
    frame.attrs["note"] = selection.note()
    return frame


RunCurves = dict[tuple[str, str, int], pd.DataFrame]
"""{(task, method, seed): the run's learning-curve points} (`by_run`)."""

EvaluationKey = tuple[str, str, int, str]
"""(task, method, seed, policy): `EVALUATION_KEYS` of one row."""


def summaries(frame: pd.DataFrame) -> Iterator[tuple[EvaluationKey, dict[str, Any]]]:
    """(`EvaluationKey`, the row's non-None fields) per row of a `run_frame`."""
    for record in frame.to_dict("records"):
        key = (str(record["task"]), str(record["method"]), int(record["seed"]))
        yield (*key, str(record["policy"])), {str(k): v for k, v in record.items() if v is not None}


def number(text: str) -> int | float | str:
    """A result CSV's cell as an ``int``, else a ``float`` (empty: NaN), else its text."""
    if text == "":
        return math.nan
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def csv_frame(path: Path, keys: dict[str, Any]) -> pd.DataFrame:
    """One result CSV's rows as `number` cells, with ``keys`` in front as columns (a CSV
    without rows: the ``keys`` columns only)."""
    _, rows = read_csv(path)
    records = [{**keys, **{k: number(v) for k, v in row.items()}} for row in rows]
    return pd.DataFrame.from_records(records, columns=None if records else list(keys))


def episode_frame(
    root: str | Path,
    preset: str,
    policy: str = TABLE_POLICY,
    seeds: Collection[int] | None = None,
) -> pd.DataFrame:
    """One row per run that counts × episode of its ``evaluation[_best].csv``: the
    `EVALUATION_KEYS`, then the file's columns as numbers."""
    selection = run_evaluations(root, preset, policy, seeds)
    parts = [csv_frame(e.episodes, e.keys) for e in selection.evaluations if e.episodes.exists()]
    frame = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=EVALUATION_KEYS)
    frame.attrs["note"] = selection.note()
    return frame


def curves_of(folders: Iterable[Path]) -> pd.DataFrame:
    """One row per folder (in order) × point of its ``progress.csv``: `RUN_KEYS`, then the
    file's columns as numbers."""
    paths = [Path(folder) / "progress.csv" for folder in folders]
    parts = [
        csv_frame(path, dict(zip(RUN_KEYS, run_keys(path.parent), strict=True)))
        for path in paths
        if path.exists()
    ]
    parts = [part for part in parts if len(part)]
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=RUN_KEYS)


def curve_frame(
    root: str | Path, preset: str, seeds: Collection[int] | None = None
) -> pd.DataFrame:
    """`curves_of` the trained runs that count (`select_runs` by ``done.json``)."""
    selection = select_runs(root, preset, marker="done.json", seeds=seeds)
    frame = curves_of(sorted(selection.current))
    frame.attrs["note"] = selection.note()
    return frame


def by_run(frame: pd.DataFrame) -> RunCurves:
    """{(task, method, seed): the run's rows} of a `curves_of` or `episode_frame` frame."""
    return {
        (str(keys[0]), str(keys[1]), int(str(keys[2]))): rows
        for keys, rows in frame.groupby(list(RUN_KEYS), sort=False)
    }


@dataclass(frozen=True)
class Frames:
    """One evaluation's `run_frame` and its runs' learning curves, loaded once."""

    runs: pd.DataFrame
    curves: RunCurves

    def of_seeds(self, seeds: Collection[int]) -> Frames:
        """These frames with trained methods' runs of ``seeds`` only (references stay)."""
        pairs = zip(self.runs["method"], self.runs["seed"], strict=True)
        keep = [not METHODS[method].trainable or int(seed) in seeds for method, seed in pairs]
        return Frames(self.runs[keep], self.curves)


def load_frames(
    root: str | Path,
    preset: str,
    policy: str = TABLE_POLICY,
    seeds: Collection[int] | None = None,
    methods: Collection[str] | None = None,
) -> Frames:
    """`Frames` of the ``policy`` evaluations of ``<root>/<preset>`` (as `run_frame`)."""
    runs = run_frame(root, preset, policy, seeds, methods)
    return Frames(runs, by_run(curves_of(runs["folder"])))
