"""Table II (hardware) from the trial files of a preset's policies (`select_trial_files`;
the files left out are listed under the table), one CSV row per protocol setting
(`hardware_rows`), one Markdown and LaTeX row per method, backend and twin noise level
(`hardware_texts`): the paper's protocol first (every trial executes the policy's
trajectory, only the UR5e's own limits apply, a protective stop at them is a failed trial,
`distgprl.trial_protocol`), then the safety layer's settings as column groups. Rates over
all trials with the exact (Clopper-Pearson) 95 % binomial interval; MinCl over the trials
that moved the robot (`moved_robot`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.markdown import csv_text, latex_table
from distgprl.report.markdown import markdown_table as _markdown_table
from distgprl.report.runs import current_hash, known_preset
from distgprl.report.table1 import INTERVAL_METRICS
from distgprl.schema import moved_robot, read_csv, trial_file_exclusion
from distgprl.trial_protocol import PAPER, PROTECTIVE_STOP, PROTOCOLS, file_protocol

HARDWARE_TASK = "dbm"
"""The task of the hardware cell (and of the policies its trials run)."""


@dataclass(frozen=True)
class TrialFiles:
    """The hardware trial files Table II of a preset counts, and why others do not.

    Attributes:
        counted: (method, meta, rows) of every counted file, in table order then file name
            (``meta``: the file's metadata, which says how its trials ran: backend, repair,
            twin sensor noise).
        excluded: one line per left-out file of the preset: ``method/file (reason)``.
    """

    counted: tuple[tuple[str, dict[str, Any], tuple[dict[str, Any], ...]], ...]
    excluded: tuple[str, ...]

    def note(self) -> str:
        """A sentence for the table: what was left out (empty if nothing)."""
        if not self.excluded:
            return ""
        return f"Not tabulated ({len(self.excluded)}): " + "; ".join(self.excluded)


def select_trial_files(root: str | Path, preset: str) -> TrialFiles:
    """The trial files ``<root>/hardware/<method>/*.csv`` of ``preset``'s policies (their
    meta's ``preset``; another preset's files belong to its own table) that Table II counts:
    not those run with the pre-flight check overridden (``force``: the safety layer's
    refusals were not applied, so they are not the method's hardware result) or as a dry
    run, and, for this checkout's presets, only those whose policy's recorded config hash
    is the one the code resolves now (as Table I; a trial of an older policy is listed);
    on the twin, one file per policy, seed and setting (`_without_twin_repeats`)."""
    base = Path(root) / "hardware"
    checked = known_preset(preset)
    counted, excluded = [], []
    for method in TABLE_ORDER:
        for path in sorted((base / method).glob("*.csv")) if (base / method).exists() else []:
            meta, rows = read_csv(path)
            if meta.get("preset") != preset:
                continue
            name = f"{method}/{path.name}"
            checked_hash = (
                current_hash(HARDWARE_TASK, method, int(meta.get("seed", -1)), preset)
                if checked and METHODS[method].trainable
                else None
            )
            reason = trial_file_exclusion(meta, checked_hash)
            if reason:
                excluded.append(f"{name} ({reason})")
            else:
                counted.append((method, meta, tuple(rows), path.name))
    kept, repeats = _without_twin_repeats(counted)
    excluded += repeats
    return TrialFiles(tuple(kept), tuple(excluded))


def _twin_setting(method: str, meta: dict[str, Any]) -> tuple[Any, ...] | None:
    """The twin setting a trial file repeats exactly (None off the twin): the twin draws a
    seed's bar positions and sensor noise from the seed, so two files of one policy, seed and
    setting run the same trials."""
    if meta.get("backend") != "twin":
        return None
    return (
        method,
        meta.get("seed"),
        file_protocol(meta),
        bool(meta.get("repair")),
        bool(meta.get("repair_push")),
        meta.get("sensor_noise") or 0,
    )


def _without_twin_repeats(
    files: list[tuple[str, dict[str, Any], tuple[dict[str, Any], ...], str]],
) -> tuple[list[tuple[str, dict[str, Any], tuple[dict[str, Any], ...]]], list[str]]:
    """The files with one twin file per (policy, seed, setting) — the one with the most
    trials, the newest on a tie (an interrupted run's partial file and its complete re-run
    hold the same first trials: counting both would count those trials twice) — and an
    exclusion line for each repeat. Trials on the real robot are new executions: all kept."""
    keepers: dict[tuple[Any, ...], tuple[Any, ...]] = {}
    for entry in files:
        setting = _twin_setting(entry[0], entry[1])
        if setting is None:
            continue
        held = keepers.get(setting)
        if held is None or (len(entry[2]), entry[3]) >= (len(held[2]), held[3]):
            keepers[setting] = entry
    kept, repeats = [], []
    for entry in files:
        method, meta, rows, name = entry
        setting = _twin_setting(method, meta)
        keeper = keepers[setting] if setting is not None else entry
        if keeper is entry:
            kept.append((method, meta, rows))
        else:
            repeats.append(
                f"{method}/{name} (repeats the twin trials of {keeper[3]}: same seed and "
                f"setting, same bar positions; {len(rows)} trials)"
            )
    return kept, repeats


def binomial_interval(successes: int, trials: int, level: float = 0.95) -> tuple[float, float]:
    """Exact (Clopper-Pearson) two-sided interval of a rate of ``successes`` in ``trials``."""
    alpha, failures = 1.0 - level, trials - successes
    low = 0.0 if successes == 0 else stats.beta.ppf(alpha / 2, successes, failures + 1)
    high = 1.0 if failures == 0 else stats.beta.ppf(1 - alpha / 2, successes + 1, failures)
    return float(low), float(high)


def hardware_table(root: str | Path, preset: str) -> list[dict[str, Any]]:
    """Rows of Table II from the trial files `select_trial_files` counts (`hardware_rows`)."""
    return hardware_rows(select_trial_files(root, preset))


def repair_label(meta: dict[str, Any]) -> str:
    """How a trial file's plans were handled before execution (its meta): ``off`` (refused
    at once), ``retime`` (re-timed when too fast, then refused if still unsafe), ``retime +
    push`` (via-points also pushed along the distance field's gradient); ``–`` for files
    written before plan repair existed, and under the paper's protocol (nothing checked, so
    nothing repaired)."""
    if "repair" not in meta or file_protocol(meta) == PAPER:
        return "–"
    if not meta["repair"]:
        return "off"
    return "retime + push" if meta.get("repair_push") else "retime"


def noise_label(meta: dict[str, Any], backend: str) -> str:
    """The twin's sensor-noise level of a trial file (``0`` for a twin file without one:
    the noiseless twin); ``–`` on the real robot."""
    if backend != "twin":
        return "–"
    level = meta.get("sensor_noise")
    return "0" if level is None else str(level)


def _median_perception_error(rows: list[dict[str, Any]]) -> float:
    """The median over trials of each trial's largest marker position error, mm (NaN where no
    trial recorded one, e.g. the real robot without ground truth)."""
    errors = []
    for row in rows:
        value = row.get("perception_error_mm", "")
        if value not in ("", "nan", None) and np.isfinite(float(value)):
            errors.append(float(value))
    return float(np.median(errors)) if errors else float("nan")


def hardware_rows(files: TrialFiles) -> list[dict[str, Any]]:
    """Rows of Table II, one per (method, backend, `file_protocol`, `repair_label`,
    `noise_label`) of the files ``files`` counts, the paper's protocol first within a method
    and backend. Refused trials and protective stops are failures without collision, also
    counted on their own; rates are over all trials with their exact 95 % interval
    (``<rate>_ci_low``, ``<rate>_ci_high``); MinCl over the ``executed`` trials that moved
    the robot (NaN if none did)."""
    groups: dict[tuple[str, str, str, str, str], list[dict[str, Any]]] = {}
    for method, meta, trial_rows in files.counted:  # counted in table order
        for row in trial_rows:
            backend = row.get("backend", "unknown")
            protocol = file_protocol(meta)
            setting = (method, backend, protocol, repair_label(meta), noise_label(meta, backend))
            groups.setdefault(setting, []).append(row)
    rows = []
    order = sorted(
        groups, key=lambda k: (TABLE_ORDER.index(k[0]), k[1], PROTOCOLS.index(k[2]), k[3], k[4])
    )
    for method, backend, protocol, repair, noise in order:
        subset = groups[(method, backend, protocol, repair, noise)]
        executed = [r for r in subset if moved_robot(r)]
        clearance = [
            float(r["min_clearance"])
            for r in executed
            if r["min_clearance"] not in ("", "nan") and np.isfinite(float(r["min_clearance"]))
        ]
        row = {
            "method": method,
            "label": METHODS[method].label,
            "backend": backend,
            "protocol": protocol,
            "repair": repair,
            "sensor_noise": noise,
            "trials": len(subset),
            "refused": sum(r.get("status") == "refused" for r in subset),
            "protective_stops": sum(r.get("status") == PROTECTIVE_STOP for r in subset),
            "min_clearance_p5": float(np.percentile(clearance, 5)) if clearance else np.nan,
            "executed": len(executed),
            "perception_error_mm_median": _median_perception_error(subset),
        }
        for key, column in (("success_rate", "success"), ("collision_rate", "collision")):
            count = int(sum(round(float(r[column])) for r in subset))
            row[key] = count / len(subset)
            row[f"{key}_ci_low"], row[f"{key}_ci_high"] = binomial_interval(count, len(subset))
        rows.append(row)
    return rows


def rate_text(row: dict[str, Any], key: str) -> str:
    """``0.67 [0.09, 0.99]``: a Table II rate with its exact 95 % binomial interval."""
    return f"{row[key]:.2f} [{row[f'{key}_ci_low']:.2f}, {row[f'{key}_ci_high']:.2f}]"


def noise_texts(rows: list[dict[str, Any]], preset: str) -> tuple[str, str] | None:
    """(CSV, Markdown) of the robustness table: the twin's success and collision rates (exact
    95 % intervals) per method and protocol setting (`setting_label`) against the
    sensor-noise level
    (`distgprl.hardware.twin.SENSOR_NOISE`); None unless some twin policy ran at more than one
    level."""
    twin = [r for r in rows if r["backend"] == "twin"]
    levels = sorted({r["sensor_noise"] for r in twin}, key=int)
    if len(levels) < 2:
        return None
    fields = "method protocol repair sensor_noise perception_error_mm_median trials".split()
    fields += list(INTERVAL_METRICS)
    fields += [f"{key}_ci_{end}" for key in INTERVAL_METRICS for end in ("low", "high")]
    table_csv = csv_text(twin, fields)
    by_setting: dict[tuple[str, str], dict[str, dict[str, Any]]] = {}
    for r in twin:
        by_setting.setdefault((r["method"], setting_label(r)), {})[r["sensor_noise"]] = r
    header = ["Method", "Protocol / repair"]
    names = ("error (mm)", "Success", "Collision")
    header += [f"Noise {level} {name}" for level in levels for name in names]
    table = []
    for (method, repair), per_level in by_setting.items():
        cells = [METHODS[method].label, repair]
        for level in levels:
            found = per_level.get(level)
            if found is None:
                cells += ["–", "–", "–"]
                continue
            error = found["perception_error_mm_median"]
            cells.append("–" if not np.isfinite(error) else f"{error:.0f}")
            cells += [rate_text(found, k) for k in INTERVAL_METRICS]
        table.append(cells)
    caption = (
        f"Digital twin robustness ({preset} preset policies, DBM): success and collision against "
        "the sensor-noise level (0 none, 1 mild, 2 strong: image noise, blur, exposure, marker "
        "corner noise, base-marker calibration error; 3 and 4: level 2 with a 2x and 4x worse "
        "calibration), the median over trials of each trial's largest marker position error "
        "(mm), exact 95 % binomial intervals"
    )
    return table_csv, _markdown_table(caption, header, table)


def setting_label(row: dict[str, Any]) -> str:
    """A `hardware_rows` row's protocol setting: ``paper`` (the paper's protocol), else the
    safety layer's repair setting (`repair_label`)."""
    return "paper" if row.get("protocol") == PAPER else str(row["repair"])


PAPER_COLUMNS = (
    ("trials", "Trials"),
    ("success_rate", "Success"),
    ("collision_rate", "Collision"),
    ("protective_stops", "Protective stops"),
    ("min_clearance_p5", "MinCl (m)"),
)
"""Table II's first columns, the paper's protocol: trials executed, success and collision
rates, protective stops at the UR5e's own limits (failed trials), MinCl."""

HARDWARE_COLUMNS = (
    ("trials", "Trials"),
    ("refused", "Refused"),
    ("success_rate", "Success"),
    ("collision_rate", "Collision"),
    ("min_clearance_p5", "MinCl (m)"),
)
"""Table II's columns of each safety-layer setting, after the paper's (MinCl: 5th
percentile of the minimum clearance of the trials that moved the robot, m). The CSV adds
``executed``, the number of those trials, and ``protective_stops``."""

SAFETY_SETTINGS = ("off", "retime", "retime + push", "–")
"""The safety layer's settings (`repair_label`) in the order of their column groups."""

HARDWARE_CAPTION = (
    "Hardware trials (DBM). First columns: the paper's protocol — every trial executes the "
    "policy's trajectory without a pre-flight check, only the UR5e's own joint speed "
    "(pi rad/s) and acceleration (40 rad/s^2) limits apply, and a protective stop at them is "
    "a failed trial (a collision only where the arm touched something). Then this project's "
    "safety layer, repair off (refused at once) and retime: its pre-flight check against its "
    "own, stricter limits; refused trials count as failures. Success and Collision with "
    "the exact 95 % binomial interval over the trials; MinCl is over the trials that "
    "moved the robot (n = their number where fewer than the trials; – if none did)"
)


def hardware_min_clearance(row: dict[str, Any]) -> str:
    """The MinCl cell: the value, ``(n=k)`` if only k of the trials moved the robot."""
    value = row["min_clearance_p5"]
    text = "–" if np.isnan(value) else f"{value:.3f}"
    if row["executed"] != row["trials"]:
        text += f" (n={row['executed']})"
    return text


def _cell(row: dict[str, Any] | None, key: str) -> str:
    """One Table II cell of a protocol setting's row (``–`` where the setting did not run)."""
    if row is None:
        return "–"
    if key in INTERVAL_METRICS:
        return rate_text(row, key)
    if key == "min_clearance_p5":
        return hardware_min_clearance(row)
    return str(row[key])


def _groups(rows: list[dict[str, Any]]) -> list[tuple[str, tuple[tuple[str, str], ...]]]:
    """The column groups of Table II: (setting, columns), the paper's protocol first, then
    every safety-layer setting some row has (`SAFETY_SETTINGS` order)."""
    present = {setting_label(r) for r in rows}
    groups: list[tuple[str, tuple[tuple[str, str], ...]]] = [("paper", PAPER_COLUMNS)]
    groups += [(s, HARDWARE_COLUMNS) for s in SAFETY_SETTINGS if s in present]
    return groups


GROUP_TITLES = {
    "paper": "Paper",
    "off": "Safety layer, repair off",
    "retime": "Safety layer, retime",
    "retime + push": "Safety layer, retime + push",
    "–": "Safety layer",
}
"""Column-group titles of Table II (`setting_label` -> title)."""


def _wide_rows(
    rows: list[dict[str, Any]],
) -> list[tuple[dict[str, Any], dict[str, dict[str, Any]]]]:
    """Table II's rows: one per (method, backend, noise) in `hardware_rows` order, each with
    its protocol settings' rows by `setting_label`."""
    keyed: dict[tuple[str, str, str], dict[str, dict[str, Any]]] = {}
    first: dict[tuple[str, str, str], dict[str, Any]] = {}
    for row in rows:
        key = (row["method"], row["backend"], row["sensor_noise"])
        first.setdefault(key, row)
        keyed.setdefault(key, {})[setting_label(row)] = row
    order = sorted(keyed, key=lambda k: (TABLE_ORDER.index(k[0]), k[1], k[2]))
    return [(first[key], keyed[key]) for key in order]


def hardware_texts(rows: list[dict[str, Any]], preset: str, note: str = "") -> tuple[str, str, str]:
    """(CSV, Markdown, LaTeX) of Table II from `hardware_table` rows: the CSV one row per
    protocol setting, Markdown and LaTeX one per method, backend and noise level with the
    paper's protocol's columns first (`_groups`)."""
    fields = "method backend protocol repair sensor_noise trials refused protective_stops".split()
    fields += ["success_rate", "collision_rate", "min_clearance_p5", "executed"]
    fields += [f"{key}_ci_{end}" for key in INTERVAL_METRICS for end in ("low", "high")]
    mincl = "min_clearance_p5"  # empty, not nan, where no trial moved
    cleared = [row | {mincl: "" if np.isnan(row[mincl]) else row[mincl]} for row in rows]
    table_csv = csv_text(cleared, fields)

    groups = _groups(rows)
    wide = _wide_rows(rows)

    def cells(head: dict[str, Any], settings: dict[str, dict[str, Any]]) -> list[str]:
        out = [head["label"], head["backend"], head["sensor_noise"]]
        for setting, columns in groups:
            out += [_cell(settings.get(setting), key) for key, _ in columns]
        return out

    header = ["Method", "Backend", "Noise"]
    header += [f"{GROUP_TITLES[g]}: {label}" for g, columns in groups for _, label in columns]
    caption = f"{HARDWARE_CAPTION} ({preset} preset policies)"
    body = [cells(head, settings) for head, settings in wide]
    markdown = _markdown_table(f"Table II: {caption}", header, body)
    if note:
        markdown += f"\n{note}.\n"
    return table_csv, markdown, _latex(caption, groups, body)


def _latex(
    caption: str, groups: list[tuple[str, tuple[tuple[str, str], ...]]], body: list[list[str]]
) -> str:
    """Table II as LaTeX: a row of column-group titles over the column names."""
    latex_caption = caption.replace("—", "---").replace("–", "--").replace(" %", "\\,\\%")
    latex_caption = latex_caption.replace("pi rad/s", "$\\pi$ rad/s").replace("s^2", "s$^2$")
    titles = (f"\\multicolumn{{{len(columns)}}}{{c}}{{{GROUP_TITLES[g]}}}" for g, columns in groups)
    names = ["Method", "Backend", "Noise", *(label for _, cs in groups for _, label in cs)]
    header = [" & & & " + " & ".join(titles), " & ".join(names)]
    columns = "lll" + "c" * sum(len(columns) for _, columns in groups)
    rows = ([cell.replace("–", "--") for cell in row] for row in body)
    return latex_table(latex_caption, "tab:hardware_results", columns, header, rows)
