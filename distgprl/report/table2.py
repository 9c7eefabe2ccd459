"""Table II (hardware) and its twin-noise table from a preset's trial files: rates over all
trials with the exact (Clopper-Pearson) 95 % interval, MinCl over the trials that moved the
robot; the paper's protocol first, then the safety layer's settings."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.markdown import (
    csv_text,
    interval_text,
    latex_table,
    markdown_table,
    number_text,
)
from distgprl.report.runs import current_hash, known_preset
from distgprl.report.table1 import INTERVAL_METRICS
from distgprl.schema import moved_robot, read_csv, trial_file_exclusion
from distgprl.trial_protocol import (
    BEST_POLICY,
    FINAL_POLICY,
    GIVEN_POLICY,
    PAPER,
    PROTECTIVE_STOP,
    PROTOCOLS,
    TABLE2_POLICY,
    TRIAL_POLICIES,
    counts_for,
    file_policy,
    file_protocol,
)

TrialFile = tuple[str, dict[str, Any], tuple[dict[str, Any], ...]]
"""(method, meta, rows) of one trial file (``meta``: backend, repair, twin sensor noise)."""


@dataclass(frozen=True)
class TrialFiles:
    """The files Table II (or its table of another trial policy) counts (table order, then
    file name), one ``method/file (reason)`` per file of the preset it leaves out, and how
    many files of each other named policy (`TRIAL_POLICIES`) the preset has, tabulated apart."""

    counted: tuple[TrialFile, ...]
    excluded: tuple[str, ...]
    apart: tuple[tuple[str, int], ...] = ()

    def note(self) -> str:
        """Sentences for the table: which trained policies the counted files ran
        (`policy_note`), the other policies' files and what was left out (empty if none)."""
        parts = [policy_note(self.counted)]
        parts += [
            f"Trial files of the {policy} policy, tabulated apart in "
            f"`{table2_stem(policy)}_<preset>`: {n}"
            for policy, n in self.apart
        ]
        if self.excluded:
            parts.append(f"Not tabulated ({len(self.excluded)}): " + "; ".join(self.excluded))
        return ". ".join(part for part in parts if part)


POLICY_NAMES = {
    FINAL_POLICY: "the run's final policy (`model.zip`)",
    BEST_POLICY: "the run's shipped best policy (Table I's)",
    GIVEN_POLICY: "a policy file given by `--model`",
}
"""What `distgprl.trial_protocol.file_policy` names, as Table II's note says it."""


def policy_note(files: Iterable[TrialFile]) -> str:
    """Which trained policies ``files`` ran, counted per `POLICY_NAMES`, beside the policy
    Table I reports (empty without a trained policy's file)."""
    kinds = Counter(kind for _, meta, _ in files if (kind := file_policy(meta)))
    if not kinds:
        return ""
    total = sum(kinds.values())
    ran = ", ".join(
        f"{POLICY_NAMES[kind]}: {n} of {total} files" for kind, n in sorted(kinds.items())
    )
    return (
        f"Trained policies run (trial files): {ran}; Table I reports each run's best trained "
        "policy (protocol v8 rule 2)"
    )


def table2_stem(policy: str = TABLE2_POLICY) -> str:
    """The file stem (before ``_<preset>``) of the Table II of ``policy``'s trials:
    ``table2`` for Table II's own policy, ``table2_<policy>`` beside it."""
    return "table2" if policy == TABLE2_POLICY else f"table2_{policy}"


def select_trial_files(root: str | Path, preset: str, policy: str = TABLE2_POLICY) -> TrialFiles:
    """The trial files ``<root>/hardware/<method>/*.csv`` of ``preset`` Table II counts, of
    the trained ``policy`` (`TRIAL_POLICIES`; a reference's files run none and count for
    each): not those `trial_file_exclusion` refuses (for this checkout's presets also a
    policy's whose config hash is not the current one on the hardware task, DBM), and of the
    files of one `_twin_setting` only the one with the most trials, the newest on a tie."""
    checked = known_preset(preset)
    files: list[tuple[str, dict[str, Any], tuple[dict[str, Any], ...], str]] = []
    excluded = []
    apart: Counter[str] = Counter()
    for method in TABLE_ORDER:
        for path in sorted((Path(root) / "hardware" / method).glob("*.csv")):
            meta, rows = read_csv(path)
            if meta.get("preset") != preset:
                continue
            kind = file_policy(meta)
            if not counts_for(kind, policy):
                if kind in TRIAL_POLICIES:  # else a given file: Table II's
                    apart[str(kind)] += 1
                continue
            seed, trainable = int(meta.get("seed", -1)), checked and METHODS[method].trainable
            reason = trial_file_exclusion(
                meta, current_hash("dbm", method, seed, preset) if trainable else None, policy
            )
            if reason:
                excluded.append(f"{method}/{path.name} ({reason})")
            else:
                files.append((method, meta, tuple(rows), path.name))
    ordered = sorted(files, key=lambda file: (len(file[2]), file[3]))  # the one kept last
    kept = {_twin_setting(m, meta, name): name for m, meta, _, name in ordered}
    counted: list[TrialFile] = []
    for method, meta, trials, name in files:
        if kept[setting := _twin_setting(method, meta, name)] == name:
            counted.append((method, meta, trials))
        else:
            excluded.append(
                f"{method}/{name} (repeats the twin trials of {kept[setting]}: same seed and "
                f"setting, same bar positions; {len(trials)} trials)"
            )
    return TrialFiles(tuple(counted), tuple(excluded), tuple(sorted(apart.items())))


def _twin_setting(method: str, meta: dict[str, Any], name: str) -> tuple[Any, ...]:
    """A twin file's setting, a robot file's ``(method, name)`` (its trials are new executions).
    The twin draws bar positions and sensor noise from the seed: one setting, the same trials."""
    if meta.get("backend") != "twin":
        return (method, name)
    repair = (bool(meta.get("repair")), bool(meta.get("repair_push")))
    return (method, meta.get("seed"), file_protocol(meta), *repair, meta.get("sensor_noise") or 0)


def binomial_interval(successes: int, trials: int, level: float = 0.95) -> tuple[float, float]:
    """Exact (Clopper-Pearson) two-sided interval of a rate of ``successes`` in ``trials``."""
    alpha, failures = 1.0 - level, trials - successes
    low = 0.0 if successes == 0 else stats.beta.ppf(alpha / 2, successes, failures + 1)
    high = 1.0 if failures == 0 else stats.beta.ppf(1 - alpha / 2, successes + 1, failures)
    return float(low), float(high)


def hardware_table(root: str | Path, preset: str) -> list[dict[str, Any]]:
    """`hardware_rows` of the files `select_trial_files` counts."""
    return hardware_rows(select_trial_files(root, preset))


def repair_label(meta: dict[str, Any]) -> str:
    """``off`` (unsafe plans refused), ``retime`` (re-timed, then refused if still unsafe),
    ``retime + push`` (via-points also pushed off obstacles); ``–``: the paper's protocol, or a
    file older than plan repair."""
    if "repair" not in meta or file_protocol(meta) == PAPER:
        return "–"
    if not meta["repair"]:
        return "off"
    return "retime + push" if meta.get("repair_push") else "retime"


def _finite(cells: Iterable[Any]) -> list[float]:
    numbers = [float(cell) for cell in cells if cell not in ("", None)]
    return [number for number in numbers if np.isfinite(number)]


SETTING = ("method", "backend", "protocol", "repair", "sensor_noise")
"""The columns naming a `hardware_rows` row (``sensor_noise``: ``–`` on the robot)."""


def hardware_rows(files: TrialFiles) -> list[dict[str, Any]]:
    """One row per `SETTING` of the counted trials (method, backend, then the paper's protocol
    first): ``setting`` (``paper`` or the `repair_label`), ``trials``, ``refused`` and
    ``protective_stops`` (failures without collision), ``success_rate`` and ``collision_rate``
    with their exact 95 % ``_ci_low``/``_ci_high``, ``min_clearance_p5`` (m) over the
    ``executed`` trials that moved the robot (NaN: none), ``perception_error_mm_median`` over the
    trials' largest marker position errors (mm; NaN: none recorded)."""
    groups: dict[tuple[str, ...], list[dict[str, Any]]] = {}
    for method, meta, trial_rows in files.counted:
        for row in trial_rows:
            backend = row.get("backend", "unknown")
            level = meta.get("sensor_noise") if backend == "twin" else "–"
            noise = "0" if level is None else str(level)
            key = (method, backend, file_protocol(meta), repair_label(meta), noise)
            groups.setdefault(key, []).append(row)
    order = sorted(
        groups, key=lambda k: (TABLE_ORDER.index(k[0]), k[1], PROTOCOLS.index(k[2]), k[3], k[4])
    )
    return [_setting_row(key, groups[key]) for key in order]


def _setting_row(key: tuple[str, ...], trials: list[dict[str, Any]]) -> dict[str, Any]:
    executed = [r for r in trials if moved_robot(r)]
    clearance = _finite(r["min_clearance"] for r in executed)
    errors = _finite(r.get("perception_error_mm") for r in trials)
    row: dict[str, Any] = dict(zip(SETTING, key, strict=True))
    row["setting"] = "paper" if row["protocol"] == PAPER else row["repair"]
    row |= {
        "trials": len(trials),
        "refused": sum(r.get("status") == "refused" for r in trials),
        "protective_stops": sum(r.get("status") == PROTECTIVE_STOP for r in trials),
        "min_clearance_p5": float(np.percentile(clearance, 5)) if clearance else np.nan,
        "executed": len(executed),
        "perception_error_mm_median": float(np.median(errors)) if errors else float("nan"),
    }
    for rate, column in (("success_rate", "success"), ("collision_rate", "collision")):
        count = int(sum(round(float(r[column])) for r in trials))
        row[rate] = count / len(trials)
        row[f"{rate}_ci_low"], row[f"{rate}_ci_high"] = binomial_interval(count, len(trials))
    return row


INTERVAL_FIELDS = [f"{key}_ci_{end}" for key in INTERVAL_METRICS for end in ("low", "high")]

LABELS = {
    "trials": "Trials",
    "refused": "Refused",
    "success_rate": "Success",
    "collision_rate": "Collision",
    "protective_stops": "Protective stops",
    "min_clearance_p5": "MinCl (m)",
    "perception_error_mm_median": "error (mm)",
}
"""The label of each `hardware_rows` column the Markdown and LaTeX tables show."""

SAFETY_COLUMNS = ("trials", "refused", "success_rate", "collision_rate", "min_clearance_p5")

GROUPS = {
    "paper": (
        "Paper",
        ("trials", "success_rate", "collision_rate", "protective_stops", "min_clearance_p5"),
    ),
    "off": ("Safety layer, repair off", SAFETY_COLUMNS),
    "retime": ("Safety layer, retime", SAFETY_COLUMNS),
    "retime + push": ("Safety layer, retime + push", SAFETY_COLUMNS),
    "–": ("Safety layer", SAFETY_COLUMNS),
}
"""Table II's column groups per ``setting`` in order: title, `LABELS` keys (the paper's
protocol's protective stops: at the UR5e's own limits)."""

NOISE_COLUMNS = ("perception_error_mm_median", "success_rate", "collision_rate")


def _cell(row: dict[str, Any] | None, key: str) -> str:
    """A `hardware_rows` row's ``key`` cell (``–`` where the setting did not run)."""
    if row is None:
        return "–"
    if key in INTERVAL_METRICS:
        return interval_text(row[key], row[f"{key}_ci_low"], row[f"{key}_ci_high"])
    if key == "perception_error_mm_median":
        return number_text(row[key], 0)
    if key != "min_clearance_p5":
        return str(row[key])
    moved = f" (n={row['executed']})" if row["executed"] != row["trials"] else ""
    return number_text(row[key], 3) + moved


def _wide_cells(
    rows: list[dict[str, Any]],
    index: tuple[str, ...],
    across: str,
    groups: Sequence[tuple[Any, tuple[str, ...]]],
) -> list[list[str]]:
    """One line per ``index`` value of ``rows`` (in their order; the method by its label):
    per (``across`` value, keys) of ``groups`` the `_cell` of each key."""
    wide: dict[tuple[Any, ...], dict[Any, dict[str, Any]]] = {}
    for row in rows:
        wide.setdefault(tuple(row[name] for name in index), {})[row[across]] = row
    return [
        [METHODS[key[0]].label, *key[1:]]
        + [_cell(found.get(value), k) for value, keys in groups for k in keys]
        for key, found in wide.items()
    ]


def noise_texts(rows: list[dict[str, Any]], preset: str) -> tuple[str, str] | None:
    """(CSV, Markdown) of the twin's `NOISE_COLUMNS` per method and ``setting`` against the
    sensor-noise level (`distgprl.hardware.twin.SENSOR_NOISE`); None unless some twin policy
    ran at more than one level."""
    twin = [r for r in rows if r["backend"] == "twin"]
    levels = sorted({r["sensor_noise"] for r in twin}, key=int)
    if len(levels) < 2:
        return None
    fields = ["method", "protocol", "repair", "sensor_noise", "perception_error_mm_median"]
    fields += ["trials", *INTERVAL_METRICS, *INTERVAL_FIELDS]
    header = ["Method", "Protocol / repair"]
    header += [f"Noise {level} {LABELS[key]}" for level in levels for key in NOISE_COLUMNS]
    body = _wide_cells(
        twin, ("method", "setting"), "sensor_noise", [(level, NOISE_COLUMNS) for level in levels]
    )
    caption = (
        f"Digital twin robustness ({preset} preset policies, DBM): success and collision against "
        "the sensor-noise level (0 none, 1 mild, 2 strong: image noise, blur, exposure, marker "
        "corner noise, base-marker calibration error; 3 and 4: level 2 with a 2x and 4x worse "
        "calibration), the median over trials of each trial's largest marker position error "
        "(mm), exact 95 % binomial intervals"
    )
    return csv_text(twin, fields), markdown_table(caption, header, body)


POLICY_TITLES = {
    TABLE2_POLICY: "Table II",
    BEST_POLICY: "Table II of the best policies, Table I's (beside Table II, whose trials run "
    "each run's final policy)",
}
"""The title that opens the Table II of each trial policy's trials (`table2_stem`)."""


def hardware_texts(
    rows: list[dict[str, Any]], preset: str, note: str = "", policy: str = TABLE2_POLICY
) -> tuple[str, str, str]:
    """(CSV, Markdown, LaTeX) of Table II (of the trained ``policy``'s trials, `POLICY_TITLES`)
    from `hardware_rows`: the CSV one row per row (MinCl empty where no trial moved), Markdown
    and LaTeX one per method, backend and noise level: the `GROUPS` some row has; ``note``
    (the files left out) under the Markdown."""
    fields = [*SETTING, "trials", "refused", "protective_stops"]
    fields += ["success_rate", "collision_rate", "min_clearance_p5", "executed", *INTERVAL_FIELDS]
    mincl = "min_clearance_p5"
    table = [row | {mincl: "" if np.isnan(row[mincl]) else row[mincl]} for row in rows]
    present = {row["setting"] for row in rows}
    groups = [(s, keys) for s, (_, keys) in GROUPS.items() if s == "paper" or s in present]
    order = sorted(
        rows, key=lambda r: (TABLE_ORDER.index(r["method"]), r["backend"], r["sensor_noise"])
    )
    body = _wide_cells(order, ("method", "backend", "sensor_noise"), "setting", groups)
    names = [LABELS[key] for _, keys in groups for key in keys]
    header = ["Method", "Backend", "Noise"]
    header += [f"{GROUPS[g][0]}: {LABELS[k]}" for g, keys in groups for k in keys]
    caption = (
        "Hardware trials (DBM). First columns: the paper's protocol — every trial executes the "
        "policy's trajectory without a pre-flight check, only the UR5e's own joint speed "
        "(pi rad/s) and acceleration (40 rad/s^2) limits apply, and a protective stop at them is "
        "a failed trial (a collision only where the arm touched something). Then this project's "
        "safety layer, repair off (refused at once) and retime: its pre-flight check against its "
        "own, stricter limits; refused trials count as failures. Success and Collision with "
        "the exact 95 % binomial interval over the trials; MinCl is over the trials that "
        f"moved the robot (n = their number where fewer than the trials; – if none did) ({preset} "
        "preset policies)"
    )
    markdown = markdown_table(f"{POLICY_TITLES[policy]}: {caption}", header, body)
    markdown += f"\n{note}.\n" if note else ""
    latex_caption = caption.replace(" %", "\\,\\%").replace("pi rad/s", "$\\pi$ rad/s")
    latex_caption = latex_caption.replace("s^2", "s$^2$")
    titles = (f"\\multicolumn{{{len(keys)}}}{{c}}{{{GROUPS[g][0]}}}" for g, keys in groups)
    latex_header = [
        " & & & " + " & ".join(titles),
        " & ".join(["Method", "Backend", "Noise", *names]),
    ]
    columns = "lll" + "c" * len(names)
    label = "tab:hardware_results" + table2_stem(policy).removeprefix("table2")
    latex = latex_table(latex_caption, label, columns, latex_header, body)
    return csv_text(table, fields), markdown, latex
