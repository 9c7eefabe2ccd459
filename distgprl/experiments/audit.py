"""Two checks of finished run folders, for the fault tests of the executors
(`scripts/cluster_test.py`):

- `compare_runs`: do two run folders of the same run (say, one trained on a Ray cluster
  that lost a node, one trained locally) hold the same results in everything but timings?
  Every result file is compared value by value: the learning curve (``progress.csv``), the
  per-episode outcomes of every evaluation (``evaluation*.csv``), the summaries
  (``summary*.json``), ``done.json`` and ``config.json``, the trained weights (the tensors
  of ``model.zip``) and the kept learning-curve actors. `TIMING_FIELDS` are left out (they
  measure the machine, not the run), and so is `HISTORY_FIELDS` (``done.json``'s record of
  where a run was resumed: a run that was resumed differs from one that was not exactly
  there, and `audit_run` checks the resumes were exact).
- `audit_run`: is a finished run folder whole? Its verdict is ``done``, its learning curve
  has no step twice (a run trained twice over itself would), its evaluations no episode
  twice, every checkpoint generation matches its manifest, no temporary file or
  ``error.json`` is left.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

from distgprl.experiments.checkpoints import verify_checkpoints
from distgprl.experiments.policies import curve_policy_dir
from distgprl.runstate import run_state
from distgprl.schema import CSV_META_SUFFIX, SchemaVersionError, read_csv, read_json

TIMING_FIELDS = frozenset(
    {
        # progress.csv: wall time trained when the curve point was taken
        "wall_time_s",
        # evaluation*.csv: milliseconds the adaptation, the policy and the repair took
        "adaptation_ms_w1",
        "adaptation_ms_w2",
        "adaptation_ms_w3",
        "policy_ms",
        "repair_ms",
        # hardware trial CSVs (DBM twin trials): the same for perception and the check
        "perception_ms",
        "check_ms",
        # summary*.json: medians of those, and the evaluation's own wall time
        "median_adaptation_ms_per_episode",
        "median_policy_ms_per_episode",
        "evaluation_wall_time_s",
        # done.json: training time
        "train_wall_time_s",
        "train_cpu_time_s",
        "cpu_s_per_step",
        # every result's meta block: when it was written
        "utc_time",
    }
)
"""Columns and keys that are timings of the machine that ran the run, by name, in every
result file of a run folder (`distgprl.schema`). ``executed_s``, ``time_added_s`` and the
like are not: they are durations of the robot's motion, results like any other."""

HISTORY_FIELDS = frozenset({"resumes"})
"""``done.json`` keys that record how a run was trained (where it was resumed), not what
it trained to."""

SKIPPED = ("tb", "checkpoints", ".lock")
"""Run-folder entries not compared: TensorBoard logs (wall-clock event times), the
checkpoints (the state to resume from, not a result; the kept curve actors inside are
compared), the lock file."""

MODEL_METADATA = ("data", "_stable_baselines3_version", "system_info.txt")
"""Members of an SB3 ``model.zip`` that are not the weights: its JSON ``data`` (with the
training's start time) and the library's notes; the ``*.pth`` tensors are compared."""


def _compare_values(a: Any, b: Any, where: str, out: list[str]) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b)):
            if key in TIMING_FIELDS or key in HISTORY_FIELDS:
                continue
            if key not in a or key not in b:
                which = "the second" if key in b else "the first"
                out.append(f"{where}: key {key!r} only in {which}")
                continue
            _compare_values(a[key], b[key], f"{where}.{key}", out)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out.append(f"{where}: {len(a)} items != {len(b)}")
        for index, (x, y) in enumerate(zip(a, b, strict=False)):
            _compare_values(x, y, f"{where}[{index}]", out)
    elif a != b or type(a) is not type(b):
        out.append(f"{where}: {a!r} != {b!r}")


def _compare_csv(name: str, a: Path, b: Path, out: list[str]) -> None:
    meta_a, rows_a = read_csv(a)
    meta_b, rows_b = read_csv(b)
    _compare_values(meta_a, meta_b, f"{name} meta", out)
    columns_a = list(rows_a[0]) if rows_a else []
    columns_b = list(rows_b[0]) if rows_b else []
    if columns_a != columns_b:
        out.append(f"{name}: columns {columns_a} != {columns_b}")
        return
    if len(rows_a) != len(rows_b):
        out.append(f"{name}: {len(rows_a)} rows != {len(rows_b)}")
    for number, (row_a, row_b) in enumerate(zip(rows_a, rows_b, strict=False), start=1):
        for column in columns_a:
            if column not in TIMING_FIELDS and row_a[column] != row_b[column]:
                out.append(f"{name} row {number} {column}: {row_a[column]} != {row_b[column]}")


def _compare_model(name: str, a: Path, b: Path, out: list[str]) -> None:
    with zipfile.ZipFile(a) as zip_a, zipfile.ZipFile(b) as zip_b:
        names_a, names_b = sorted(zip_a.namelist()), sorted(zip_b.namelist())
        if names_a != names_b:
            out.append(f"{name}: members {names_a} != {names_b}")
            return
        for member in names_a:
            if member not in MODEL_METADATA and zip_a.read(member) != zip_b.read(member):
                out.append(f"{name}: {member} differs (the trained weights)")


def _compare_file(name: str, a: Path, b: Path, out: list[str]) -> None:
    if name.endswith(CSV_META_SUFFIX):
        return  # compared with its CSV (`read_csv` reads it)
    if name.endswith(".csv"):
        _compare_csv(name, a, b, out)
    elif name.endswith(".json"):
        try:
            doc_a, doc_b = read_json(a), read_json(b)
        except SchemaVersionError:  # not a versioned result: compare as plain JSON
            doc_a, doc_b = json.loads(a.read_text()), json.loads(b.read_text())
        _compare_values(doc_a, doc_b, name, out)
    elif name.endswith(".zip"):
        _compare_model(name, a, b, out)
    elif a.read_bytes() != b.read_bytes():
        out.append(f"{name}: the bytes differ")


def _result_files(folder: Path) -> dict[str, Path]:
    """The folder's files to compare, by path relative to it: every file but `SKIPPED`, and
    the kept learning-curve actors (``curve_policies/<name>``, `curve_policy_dir`)."""
    files = {}
    for path in sorted(folder.rglob("*")):
        relative = path.relative_to(folder)
        if not path.is_file() or relative.parts[0] in SKIPPED:
            continue
        files[relative.as_posix()] = path
    curve_policies = curve_policy_dir(folder)
    if curve_policies.is_dir():
        for path in sorted(curve_policies.iterdir()):
            files[f"curve_policies/{path.name}"] = path
    return files


def compare_runs(a: str | Path, b: str | Path) -> list[str]:
    """Where two run folders' results differ in anything but `TIMING_FIELDS` and
    `HISTORY_FIELDS`: one line per difference (a file only in one of them, a value, a
    tensor file), empty if they agree. Floats are compared exactly, as written."""
    a, b = Path(a), Path(b)
    files_a, files_b = _result_files(a), _result_files(b)
    out = [f"{name}: only in {a}" for name in sorted(set(files_a) - set(files_b))]
    out += [f"{name}: only in {b}" for name in sorted(set(files_b) - set(files_a))]
    for name in sorted(set(files_a) & set(files_b)):
        try:
            _compare_file(name, files_a[name], files_b[name], out)
        except (OSError, ValueError, zipfile.BadZipFile) as error:
            out.append(f"{name}: cannot be compared ({type(error).__name__}: {error})")
    return out


def audit_run(folder: str | Path, trainable: bool = True) -> list[str]:
    """What is wrong with a finished run folder, one line each (empty: nothing): its
    verdict is not ``done`` (`run_state`), a learning-curve step or an evaluation episode
    appears twice, a checkpoint generation does not match its manifest
    (`verify_checkpoints`), a temporary file or ``error.json`` is left."""
    folder = Path(folder)
    problems = []
    state = run_state(folder, trainable, None)
    if state.verdict != "done":
        problems.append(f"verdict {state.verdict} {state.describe()}".rstrip())
    progress = folder / "progress.csv"
    if trainable and progress.exists():
        steps = [int(row["step"]) for row in read_csv(progress)[1]]
        if steps != sorted(set(steps)):
            problems.append(f"progress.csv: steps not strictly increasing: {steps}")
    for evaluation in sorted(folder.glob("evaluation*.csv")):
        episodes = [row["episode"] for row in read_csv(evaluation)[1]]
        if len(episodes) != len(set(episodes)):
            problems.append(f"{evaluation.name}: an episode appears twice")
    if trainable:
        problems += [f"checkpoint: {damage.describe()}" for damage in verify_checkpoints(folder)]
    leftovers = [p for p in folder.rglob("*") if ".tmp" in p.name or p.name == "error.json"]
    problems += [f"left behind: {p.relative_to(folder)}" for p in leftovers]
    return problems
