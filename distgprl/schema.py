"""The results schema: file formats, run-folder layout, file names, CSV fields and metrics.

Everything a reader of results needs (``report/``, ``distgprl status``) and a writer must
respect (the runner, the sweep, hardware trials), without importing either: this module
imports neither torch, pybullet nor gymnasium.

**Versioned files.** Every result file the project writes carries a ``meta`` block (schema
version, package version, git commit, UTC time, library versions, and whatever the caller adds
such as the config hash and seed) and is written atomically (:mod:`distgprl.io`). A reader that
finds an unknown schema version raises :class:`SchemaVersionError` instead of guessing. A CSV
result is a plain CSV (header line, rows: a default ``pandas.read_csv`` reads it) whose meta
block is in the JSON sidecar ``<name>.csv.meta.json`` (:func:`csv_meta_path`); CSVs written
before the sidecar carry it as a first ``# meta: {json}`` line, and :func:`read_csv` reads both.

**Run folders** ``<root>/<preset>/<task>/<method>/seed<k>/`` (:func:`run_dir`; the files are
described in :mod:`distgprl.experiments`): ``config.json``, ``progress.csv``
(:data:`PROGRESS_FIELDS`), ``evaluation[_best][_n<N>].csv`` (:data:`EVALUATION_FIELDS`) with
its ``summary[_best][_n<N>].json`` (:func:`evaluation_file_names`), ``done.json``.

**Windows.** :data:`N_WINDOWS`: the evaluation rows record the adaptation time of exactly
three windows (``adaptation_ms_w1..w3``), the paper's three RL steps per episode.

**Evaluation protocol.** The fixed evaluation and learning-curve TCs are drawn from
:data:`EVALUATION_SEED` and :data:`TRAINING_CURVE_SEED`; no run may train on either.

**Hardware trials**: one row per trial (:data:`TRIAL_FIELDS`); :func:`moved_robot`.
"""

from __future__ import annotations

import csv
import io
import json
import subprocess
from collections.abc import Iterable, Mapping, Sequence
from datetime import UTC, datetime
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from distgprl.errors import UserInputError
from distgprl.io import atomic_write_text
from distgprl.machine import machine_info
from distgprl.trial_protocol import TABLE2_POLICY, counts_for, file_policy
from distgprl.version import __version__

__all__ = [
    "CSV_META_SUFFIX",
    "EVALUATION_FIELDS",
    "REPAIR_EVALUATION_FIELDS",
    "REPAIR_MODES",
    "EVALUATION_SEED",
    "N_WINDOWS",
    "POLICY_CHOICES",
    "PROGRESS_FIELDS",
    "SCHEMA_VERSION",
    "SOURCE_PATHS",
    "TRAINING_CURVE_SEED",
    "TRIAL_FIELDS",
    "SchemaVersionError",
    "collision_free_min_clearance_p5",
    "csv_meta_path",
    "evaluation_file_names",
    "git_commit",
    "is_safe_success",
    "library_versions",
    "moved_robot",
    "read_csv",
    "read_json",
    "repair_evaluation_file_names",
    "result_meta",
    "run_dir",
    "safe_success_rate",
    "source_commit",
    "write_csv",
    "write_json",
]

SCHEMA_VERSION = 1
_LIBRARIES = ("numpy", "scipy", "torch", "pybullet", "stable_baselines3", "gymnasium")


class SchemaVersionError(UserInputError, ValueError):
    """A result file was written with a schema version this code cannot read."""


SOURCE_PATHS = ("distgprl", "pyproject.toml", "constraints.txt")
"""What `source_commit` checks for local changes (relative to the repository root)."""


@lru_cache(maxsize=1)
def git_commit() -> str:
    """`source_commit` of this package's repository (once per process)."""
    return source_commit(Path(__file__).resolve().parents[1])


def source_commit(root: str | Path) -> str:
    """The commit checked out at ``root``, with ``+dirty`` if the package source or its
    dependency pins have local changes (result files and other untracked files do not
    count: re-evaluating a committed run must not mark its own files dirty); ``unknown``
    outside a git work tree."""
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", *SOURCE_PATHS],
            cwd=root,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return commit + ("+dirty" if dirty else "")


@lru_cache(maxsize=1)
def library_versions() -> dict[str, str]:
    """Installed versions of the libraries that determine results."""
    out = {}
    for name in _LIBRARIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "absent"
    return out


def result_meta(**extra: Any) -> dict[str, Any]:
    """The versioning block stored in every result file."""
    return {
        "schema_version": SCHEMA_VERSION,
        "package_version": __version__,
        "git_commit": git_commit(),
        "utc_time": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "libraries": library_versions(),
        "machine": machine_info(),  # what decides the floating-point bits (distgprl.machine)
        **extra,
    }


def write_json(path: str | Path, payload: Mapping[str, Any], **meta: Any) -> Path:
    """Write a versioned JSON result: ``{"meta": result_meta(**meta), **payload}``."""
    document = {"meta": result_meta(**meta), **payload}
    return atomic_write_text(path, json.dumps(document, indent=2, sort_keys=False) + "\n")


def read_json(path: str | Path) -> dict[str, Any]:
    """Read a versioned JSON result, checking its schema version."""
    path = Path(path)
    try:
        document = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise SchemaVersionError(
            f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})"
        ) from None
    meta = document.get("meta") if isinstance(document, dict) else None
    if not isinstance(meta, dict):
        raise SchemaVersionError(f"{path}: no 'meta' object; not a distgprl result")
    version = meta.get("schema_version")
    if version != SCHEMA_VERSION:
        raise SchemaVersionError(
            f"{path}: schema_version {version!r} is not supported (this is schema "
            f"{SCHEMA_VERSION}, distgprl {__version__}); regenerate the file"
        )
    return document


CSV_META_SUFFIX = ".meta.json"
"""A CSV result's metadata sidecar: ``evaluation.csv`` -> ``evaluation.csv.meta.json``."""


def csv_meta_path(path: str | Path) -> Path:
    """The metadata sidecar of the CSV result ``path`` (`CSV_META_SUFFIX`)."""
    path = Path(path)
    return path.with_name(path.name + CSV_META_SUFFIX)


def write_csv(
    path: str | Path,
    rows: Iterable[Mapping[str, Any]],
    fieldnames: Sequence[str],
    **meta: Any,
) -> Path:
    """Write a versioned CSV: a plain CSV (one header line, then rows: what a default
    ``pandas.read_csv`` reads) and its metadata sidecar `csv_meta_path` (a versioned JSON
    result, `write_json`: ``{"meta": ..., "columns": fieldnames}``).

    The sidecar is written first, so a CSV on disk always has one (a kill in between
    leaves the previous CSV beside the new sidecar).
    """
    path = Path(path)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(fieldnames), lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: row[k] for k in fieldnames})
    write_json(csv_meta_path(path), {"columns": list(fieldnames)}, **meta)
    return atomic_write_text(path, buffer.getvalue())


def _legacy_meta(path: Path, line: str) -> dict[str, Any]:
    """The metadata of a CSV in the format before the sidecar (schema 1 files committed
    under ``results/``): a first line ``# meta: {json}``."""
    try:
        meta = json.loads(line[len("# meta: ") :])
    except json.JSONDecodeError as exc:
        raise SchemaVersionError(
            f"{path}: '# meta:' line is not valid JSON ({exc.msg}); not a distgprl result"
        ) from None
    if not isinstance(meta, dict):
        raise SchemaVersionError(f"{path}: '# meta:' line is not an object; not a distgprl result")
    return meta


def read_csv(path: str | Path) -> tuple[dict[str, Any], list[dict[str, str]]]:
    """Read a versioned CSV written by :func:`write_csv`: returns (meta, rows).

    Also reads the earlier format, whose metadata is a first ``# meta: {json}`` line (the
    committed results written before the sidecar), and checks the schema version of both.
    """
    path = Path(path)
    lines = path.read_text().splitlines()
    if lines and lines[0].startswith("# meta: "):
        meta, lines = _legacy_meta(path, lines[0]), lines[1:]
    else:
        sidecar = csv_meta_path(path)
        if not sidecar.exists():
            raise SchemaVersionError(
                f"{path}: no metadata (neither {sidecar.name} beside it nor a '# meta:' "
                "first line); not a distgprl result"
            )
        meta = read_json(sidecar)["meta"]
    if meta.get("schema_version") != SCHEMA_VERSION:
        raise SchemaVersionError(
            f"{path}: schema_version {meta.get('schema_version')!r} is not supported "
            f"(this is schema {SCHEMA_VERSION}); regenerate the file"
        )
    rows = list(csv.DictReader(lines))
    return meta, rows


# -- run folders ----------------------------------------------------------------------------
def run_dir(root: str | Path, preset: str, task: str, method: str, seed: int) -> Path:
    """``<root>/<preset>/<task>/<method>/seed<k>``."""
    return Path(root) / preset / task / method / f"seed{seed}"


#: Policies that can be evaluated: the final one (Table I) or the best learning-curve one.
POLICY_CHOICES = ("final", "best")


def evaluation_file_names(episodes: int | None = None, policy: str = "final") -> tuple[str, str]:
    """(per-episode CSV, summary JSON) file names of an evaluation in a run folder.

    ``None``: the preset's evaluation (``evaluation.csv``, ``summary.json``), the one Table I
    reads. An integer: a supplementary evaluation on the first ``episodes`` TCs of the same
    evaluation stream (``evaluation_n<episodes>.csv``, ``summary_n<episodes>.json``), kept
    beside the preset's and never replacing it. ``policy="best"``: the same for the best
    learning-curve policy, with ``_best`` after the stem (``evaluation_best.csv``,
    ``summary_best_n1000.json``).
    """
    if policy not in POLICY_CHOICES:
        raise UserInputError(f"unknown policy {policy!r}; choose from {', '.join(POLICY_CHOICES)}")
    tag = "" if policy == "final" else f"_{policy}"
    suffix = "" if episodes is None else f"_n{episodes}"
    return f"evaluation{tag}{suffix}.csv", f"summary{tag}{suffix}.json"


N_WINDOWS = 3
"""Windows (RL steps) per episode the evaluation rows record: ``adaptation_ms_w1..w3``.
The schema fixes it; ``EnvConfig.n_windows`` is the paper's 3 in every preset."""

PROGRESS_FIELDS = (
    "step",
    "episodes",
    "success_rate",
    "collision_rate",
    "mean_return",
    "min_clearance_p5",
    "wall_time_s",
    "l_sim",
    "l_hap",
    "ent_coef",
    "grad_q",
    "grad_sim",
    "grad_hap",
    "grad_hap_active",
    "hap_active_fraction",
)
"""``grad_*``: each actor-loss term's mean per-sample gradient norm on the
actor's output at the curve point (`RegularisedSAC.actor_loss_gradient_norms`);
``grad_hap_active`` (the mechanism table) the same for lambda_hap L_hap over
the samples outside C_safe (`HapPrior.outside_threshold`; empty where none is),
``hap_active_fraction`` the share of those samples. Rows written before these columns lack
them (reader: missing)."""
EVALUATION_FIELDS = (
    "episode",
    "object_offset_x",
    "object_offset_y",
    "obstacle_offset_x",
    "obstacle_offset_y",
    "success",
    "completed",
    "collision",
    "min_clearance",
    "min_signed_clearance",
    "return",
    "return_tc",
    "return_sd",
    "return_ga",
    "kinematic_retention",
    "adaptation_ms_w1",
    "adaptation_ms_w2",
    "adaptation_ms_w3",
    "policy_ms",
    "peak_joint_speed",
)
"""Columns of an evaluation CSV (one row per episode, `distgprl.experiments.rollout.
run_episode`). ``return`` is the episode's return, ``return_tc`` / ``return_sd`` /
``return_ga`` (the mechanism table) its r_tc, r_sd and lambda_ga r_ga parts
(one task's unit); files written before these columns lack them (an additive change: the
schema version stays, and readers treat them as not recorded)."""


REPAIR_EVALUATION_FIELDS = (
    "episode",
    "object_offset_x",
    "object_offset_y",
    "obstacle_offset_x",
    "obstacle_offset_y",
    "success",
    "completed",
    "collision",
    "refused",
    "refused_window",
    "refused_limits",
    "refusal_reason",
    "min_clearance",
    "min_signed_clearance",
    "planned_min_clearance",
    "peak_joint_speed",
    "executed_s",
    "repair",
    "repair_added_s",
    "repair_displacement_m",
    "time_added_s",
    "max_displacement_m",
    "policy_ms",
    "repair_ms",
)
"""Columns of an evaluation with the safety layer in the loop
(:func:`repair_evaluation_file_names`; `distgprl.experiments.safety_layer_evaluation`).
``success``/``completed``/``collision``/``refused`` 0/1 (a refused episode is neither a
success nor a collision); ``refused_window`` 1-based, ``""`` unless refused; clearances m
(``min_clearance`` of the executed motion, the start pose's if nothing moved;
``planned_min_clearance`` the predicted one of the executed plans); ``executed_s`` the
executed motion, s. ``repair``, ``repair_added_s`` and ``repair_displacement_m`` hold one
``;``-separated entry per planned window, as the trial rows do (:data:`TRIAL_FIELDS`):
decision ``none``/``retimed``/``repaired``/``refused``, time added (s), largest via-point
displacement (m); ``time_added_s`` and ``max_displacement_m`` are their sum and maximum."""


REPAIR_MODES = {"check": "_check", "repair": "_repair", "push": "_repair_push"}
"""File tags of the safety-layer evaluations: ``check`` refuses every unsafe window at once,
``repair`` retimes before refusing (``--plan-repair``), ``push`` also pushes via-points out
of the clearance margin (``--plan-repair --repair-push``)."""


def repair_evaluation_file_names(
    episodes: int | None = None, policy: str = "final", mode: str = "repair"
) -> tuple[str, str]:
    """(per-episode CSV, summary JSON) of an evaluation with the safety layer in the loop,
    beside the plain evaluation of `evaluation_file_names` (never replacing it):
    ``evaluation[_best]<tag>[_n<N>].csv`` and the matching ``summary...json``, the tag that
    of ``mode`` in :data:`REPAIR_MODES` (e.g. ``evaluation_repair.csv``)."""
    if mode not in REPAIR_MODES:
        raise UserInputError(f"unknown repair mode {mode!r}; choose from {', '.join(REPAIR_MODES)}")
    csv_name, summary_name = evaluation_file_names(episodes, policy)
    suffix = "" if episodes is None else f"_n{episodes}"
    csv_stem = csv_name.removesuffix(".csv").removesuffix(suffix)
    summary_stem = summary_name.removesuffix(".json").removesuffix(suffix)
    tag = REPAIR_MODES[mode]
    return f"{csv_stem}{tag}{suffix}.csv", f"{summary_stem}{tag}{suffix}.json"


# -- metrics ----------------------------------------------------------------------------------
def is_safe_success(row: dict[str, Any]) -> bool:
    """Whether an episode row succeeded without any collision."""
    return int(row["success"]) == 1 and int(row["collision"]) == 0


def safe_success_rate(rows: list[dict[str, Any]]) -> float:
    """Share of episodes that succeeded without any collision (not a metric of the paper,
    whose success ignores collisions: in simulation a colliding robot pushes on through
    kinematic obstacles, where a real arm would stop or knock them away)."""
    return float(np.mean([is_safe_success(r) for r in rows]))


def collision_free_min_clearance_p5(rows: Sequence[Mapping[str, Any]]) -> tuple[float | None, int]:
    """MinCl as pre-registered (docs/findings/protocol.md, rule 5) and
    the number of episodes it is over: the 5th percentile (linear interpolation), over the
    episodes *without* a collision, of the episode-wise minimum clearance (``min_clearance``:
    robot links and tool vs the obstacles, m, clamped at 0: older rows hold the signed value).
    ``(None, 0)`` where every episode collided: MinCl is then undefined, not 0 (a colliding
    episode's clearance is 0 by definition and already counted by the collision rate)."""
    free = [max(float(r["min_clearance"]), 0.0) for r in rows if int(float(r["collision"])) == 0]
    return (float(np.percentile(free, 5)) if free else None), len(free)


# -- evaluation protocol ----------------------------------------------------------------------
EVALUATION_SEED = 7_130_911
"""Seed of the fixed 100-TC evaluation set. No training run may use it."""

TRAINING_CURVE_SEED = 5_204_377
"""Seed of the fixed TC set used for evaluations during training (learning curves)."""


# -- hardware trials --------------------------------------------------------------------------
TRIAL_FIELDS = (
    "trial",
    "backend",
    "status",
    "success",
    "collision",
    "min_clearance",
    "clearance_source",
    "planned_min_clearance",
    "stop_reason",
    "refused_limits",
    "repair",
    "repair_added_s",
    "repair_displacement_m",
    "object_offset_y",
    "obstacle_offset_y",
    "true_object_offset_y",
    "true_obstacle_offset_y",
    "perception_error_mm",
    "perception_error_deg",
    "images",
    "perception_ms",
    "policy_ms",
    "check_ms",
    "execution_s",
    "trial_s",
)
"""Columns of a trial CSV (``success``/``collision`` 0/1; clearances m; errors max over
the trial's images; ``*_ms`` summed over the trial, ``perception_ms`` per image;
``check_ms`` includes the plan repair). The ``repair*`` columns (absent in trial files made
before plan repair) hold one ``;``-separated entry per planned window: the decision
(``none``/``retimed``/``repaired``/``refused``), the time added (s) and the largest
via-point displacement (m)."""


def moved_robot(trial: dict[str, Any]) -> bool:
    """Whether a hardware trial moved the robot: it finished (status ``ok``) or spent
    execution time (``execution_s`` > 0; e.g. refused or stopped in a later window after
    executing the earlier ones). A trial refused in its first window, or stopped or not
    perceived before any motion, did not move; its recorded clearance is that of the start
    pose (or infinite), not of a motion."""
    if trial.get("status") == "ok":
        return True
    execution = trial.get("execution_s", "")
    return execution not in ("", None) and float(execution) > 0.0


def trial_file_exclusion(
    meta: dict[str, Any], current_policy_hash: str | None, policy: str = TABLE2_POLICY
) -> str | None:
    """Why Table II (of ``policy``'s trials, `distgprl.trial_protocol.TRIAL_POLICIES`) does
    not count a hardware trial file, from its meta; None when it does.

    Not counted: trials run with the pre-flight check overridden (``force``: the safety
    layer's refusals were not applied, so they are not the method's hardware result), dry
    runs, trials of another policy than ``policy`` (`distgprl.trial_protocol.counts_for`), and
    trials of a policy whose recorded config hash is not ``current_policy_hash`` (the hash
    the code resolves now for the policy's run; None where it is not checked: an
    untrained reference, or a preset this checkout does not know). The one rule both Table II
    (`distgprl.report.table2`) and the sweep's trial bookkeeping
    (`distgprl.experiments.table2_trials`) apply."""
    if meta.get("force"):
        return "pre-flight check overridden, --force"
    if meta.get("dry_run"):
        return "dry run"
    ran = file_policy(meta)
    if not counts_for(ran, policy):
        return f"ran the {ran} policy; this table counts the {policy} policy's trials"
    if current_policy_hash is not None:
        recorded = (meta.get("policy") or {}).get("run_config_hash")
        if recorded != current_policy_hash:
            return f"policy config hash {recorded or 'not recorded'}, not the current one"
    return None
