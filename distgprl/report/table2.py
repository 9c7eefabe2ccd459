"""Table II (hardware) from the trial files of a preset's policies (`select_trial_files`;
the files left out are listed under the table), one CSV row per protocol setting
(`hardware_rows`), one Markdown and LaTeX row per method, backend and twin noise level
(`hardware_texts`): the paper's protocol first (`distgprl.trial_protocol`), then the safety
layer's settings as column groups (`HARDWARE_CAPTION`). Rates over all trials with the exact
(Clopper-Pearson) 95 % binomial interval; MinCl over the trials that moved the robot.
"""

from __future__ import annotations

from collections.abc import Iterable
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
from distgprl.trial_protocol import PAPER, PROTECTIVE_STOP, PROTOCOLS, file_protocol

HARDWARE_TASK = "dbm"
"""The task of the hardware cell (and of the policies its trials run)."""

TrialFile = tuple[str, dict[str, Any], tuple[dict[str, Any], ...]]
"""(method, meta, rows) of one trial file (``meta``: how its trials ran: backend, repair,
twin sensor noise)."""


@dataclass(frozen=True)
class TrialFiles:
    """The hardware trial files Table II of a preset counts, and why others do not.

    Attributes:
        counted: the `TrialFile` of every counted file, in table order then file name.
        excluded: one line per left-out file of the preset: ``method/file (reason)``.
    """

    counted: tuple[TrialFile, ...]
    excluded: tuple[str, ...]

    def note(self) -> str:
        """A sentence for the table: what was left out (empty if nothing)."""
        if not self.excluded:
            return ""
        return f"Not tabulated ({len(self.excluded)}): " + "; ".join(self.excluded)


def select_trial_files(root: str | Path, preset: str) -> TrialFiles:
    """The trial files ``<root>/hardware/<method>/*.csv`` of ``preset``'s policies (their
    meta's ``preset``) that Table II counts: not those `trial_file_exclusion` refuses (run
    with the pre-flight check overridden, a dry run, or — for this checkout's presets — of a
    policy whose recorded config hash is not the one the code resolves now, as Table I); on
    the twin, one file per policy, seed and setting (`_without_twin_repeats`)."""
    checked = known_preset(preset)
    counted, excluded = [], []
    for method in TABLE_ORDER:
        for path in sorted((Path(root) / "hardware" / method).glob("*.csv")):
            meta, rows = read_csv(path)
            if meta.get("preset") != preset:
                continue
            seed, trainable = int(meta.get("seed", -1)), checked and METHODS[method].trainable
            checked_hash = current_hash(HARDWARE_TASK, method, seed, preset) if trainable else None
            reason = trial_file_exclusion(meta, checked_hash)
            if reason:
                excluded.append(f"{method}/{path.name} ({reason})")
            else:
                counted.append((method, meta, tuple(rows), path.name))
    kept, repeats = _without_twin_repeats(counted)
    return TrialFiles(tuple(kept), (*excluded, *repeats))


def _twin_setting(method: str, meta: dict[str, Any]) -> tuple[Any, ...] | None:
    """The twin setting a trial file repeats exactly (None off the twin): the twin draws a
    seed's bar positions and sensor noise from the seed, so two files of one policy, seed and
    setting run the same trials."""
    if meta.get("backend") != "twin":
        return None
    repair = (bool(meta.get("repair")), bool(meta.get("repair_push")))
    return (method, meta.get("seed"), file_protocol(meta), *repair, meta.get("sensor_noise") or 0)


def _without_twin_repeats(
    files: list[tuple[str, dict[str, Any], tuple[dict[str, Any], ...], str]],
) -> tuple[list[TrialFile], list[str]]:
    """The files (method, meta, rows, name) with one twin file per (policy, seed, setting) —
    the one with the most trials, the newest on a tie (an interrupted run's partial file and
    its complete re-run hold the same first trials: counting both would count those trials
    twice) — and an exclusion line for each repeat. Trials on the real robot are new
    executions: all kept."""
    keepers: dict[tuple[Any, ...] | None, tuple[Any, ...]] = {}
    for entry in files:
        setting = _twin_setting(entry[0], entry[1])
        if setting is not None:
            held = keepers.get(setting, entry)
            keepers[setting] = max(held, entry, key=lambda e: (len(e[2]), e[3]))
    kept, repeats = [], []
    for method, meta, rows, name in files:
        keeper = keepers.get(_twin_setting(method, meta))  # None off the twin
        if keeper is None or keeper[3] == name:
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


def _finite(cells: Iterable[Any]) -> list[float]:
    """The finite numbers among trial-row cells (empty, ``nan`` and missing cells left out)."""
    numbers = [float(cell) for cell in cells if cell not in ("", None)]
    return [number for number in numbers if np.isfinite(number)]


def hardware_rows(files: TrialFiles) -> list[dict[str, Any]]:
    """Rows of Table II, one per (method, backend, `file_protocol`, `repair_label`,
    `noise_label`) of the files ``files`` counts, the paper's protocol first within a method
    and backend. Refused trials and protective stops are failures without collision, also
    counted on their own; rates are over all trials with their exact 95 % interval
    (``<rate>_ci_low``, ``<rate>_ci_high``); ``min_clearance_p5`` (m) the 5th percentile over
    the ``executed`` trials that moved the robot (NaN if none did);
    ``perception_error_mm_median`` the median over trials of each trial's largest marker
    position error (mm; NaN where none recorded one, e.g. the real robot)."""
    groups: dict[tuple[str, str, str, str, str], list[dict[str, Any]]] = {}
    for method, meta, trial_rows in files.counted:
        for row in trial_rows:
            backend = row.get("backend", "unknown")
            setting = (method, backend, file_protocol(meta), repair_label(meta))
            groups.setdefault((*setting, noise_label(meta, backend)), []).append(row)
    order = sorted(
        groups, key=lambda k: (TABLE_ORDER.index(k[0]), k[1], PROTOCOLS.index(k[2]), k[3], k[4])
    )
    rows = []
    for key in order:
        subset = groups[key]
        executed = [r for r in subset if moved_robot(r)]
        clearance = _finite(r["min_clearance"] for r in executed)
        errors = _finite(r.get("perception_error_mm") for r in subset)
        row = dict(
            zip(("method", "backend", "protocol", "repair", "sensor_noise"), key, strict=True)
        )
        row |= {
            "label": METHODS[key[0]].label,
            "trials": len(subset),
            "refused": sum(r.get("status") == "refused" for r in subset),
            "protective_stops": sum(r.get("status") == PROTECTIVE_STOP for r in subset),
            "min_clearance_p5": float(np.percentile(clearance, 5)) if clearance else np.nan,
            "executed": len(executed),
            "perception_error_mm_median": float(np.median(errors)) if errors else float("nan"),
        }
        for rate, column in (("success_rate", "success"), ("collision_rate", "collision")):
            count = int(sum(round(float(r[column])) for r in subset))
            row[rate] = count / len(subset)
            row[f"{rate}_ci_low"], row[f"{rate}_ci_high"] = binomial_interval(count, len(subset))
        rows.append(row)
    return rows


INTERVAL_FIELDS = [f"{key}_ci_{end}" for key in INTERVAL_METRICS for end in ("low", "high")]
"""The CSV columns of the rates' exact 95 % intervals."""


def setting_label(row: dict[str, Any]) -> str:
    """A `hardware_rows` row's protocol setting: ``paper`` (the paper's protocol), else the
    safety layer's repair setting (`repair_label`)."""
    return "paper" if row.get("protocol") == PAPER else str(row["repair"])


Columns = tuple[tuple[str, str], ...]
"""(key, label) of a group's columns."""

NOISE_COLUMNS: Columns = (
    ("perception_error_mm_median", "error (mm)"),
    ("success_rate", "Success"),
    ("collision_rate", "Collision"),
)
"""The robustness table's columns per sensor-noise level."""

PAPER_COLUMNS: Columns = (
    ("trials", "Trials"),
    ("success_rate", "Success"),
    ("collision_rate", "Collision"),
    ("protective_stops", "Protective stops"),
    ("min_clearance_p5", "MinCl (m)"),
)
"""Table II's first columns, the paper's protocol: trials executed, success and collision
rates, protective stops at the UR5e's own limits (failed trials), MinCl."""

HARDWARE_COLUMNS: Columns = (
    ("trials", "Trials"),
    ("refused", "Refused"),
    ("success_rate", "Success"),
    ("collision_rate", "Collision"),
    ("min_clearance_p5", "MinCl (m)"),
)
"""Table II's columns of each safety-layer setting, after the paper's (MinCl: 5th
percentile of the minimum clearance of the trials that moved the robot, m). The CSV adds
``executed``, the number of those trials, and ``protective_stops``."""

GROUP_TITLES = {
    "paper": "Paper",
    "off": "Safety layer, repair off",
    "retime": "Safety layer, retime",
    "retime + push": "Safety layer, retime + push",
    "–": "Safety layer",
}
"""Column-group titles of Table II (`setting_label` -> title), in the groups' order."""

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


def _cell(row: dict[str, Any] | None, key: str) -> str:
    """One cell of a `hardware_rows` row (``–`` where the setting did not run): a rate with
    its exact 95 % interval, the perception error to the millimetre, MinCl with ``(n=k)`` if
    only k of the trials moved the robot, a count as it is."""
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


def noise_texts(rows: list[dict[str, Any]], preset: str) -> tuple[str, str] | None:
    """(CSV, Markdown) of the robustness table: the twin's success and collision rates (exact
    95 % intervals) and median perception error per method and protocol setting
    (`setting_label`) against the sensor-noise level (`distgprl.hardware.twin.SENSOR_NOISE`);
    None unless some twin policy ran at more than one level."""
    twin = [r for r in rows if r["backend"] == "twin"]
    levels = sorted({r["sensor_noise"] for r in twin}, key=int)
    if len(levels) < 2:
        return None
    fields = "method protocol repair sensor_noise perception_error_mm_median trials".split()
    header = ["Method", "Protocol / repair"]
    header += [f"Noise {level} {name}" for level in levels for _, name in NOISE_COLUMNS]
    by_setting: dict[tuple[str, str], dict[str, dict[str, Any]]] = {}
    for r in twin:
        by_setting.setdefault((r["method"], setting_label(r)), {})[r["sensor_noise"]] = r
    table = [
        [METHODS[method].label, setting]
        + [_cell(found.get(level), key) for level in levels for key, _ in NOISE_COLUMNS]
        for (method, setting), found in by_setting.items()
    ]
    table_csv = csv_text(twin, [*fields, *INTERVAL_METRICS, *INTERVAL_FIELDS])
    caption = (
        f"Digital twin robustness ({preset} preset policies, DBM): success and collision against "
        "the sensor-noise level (0 none, 1 mild, 2 strong: image noise, blur, exposure, marker "
        "corner noise, base-marker calibration error; 3 and 4: level 2 with a 2x and 4x worse "
        "calibration), the median over trials of each trial's largest marker position error "
        "(mm), exact 95 % binomial intervals"
    )
    return table_csv, markdown_table(caption, header, table)


def hardware_texts(rows: list[dict[str, Any]], preset: str, note: str = "") -> tuple[str, str, str]:
    """(CSV, Markdown, LaTeX) of Table II from `hardware_table` rows: the CSV one row per
    protocol setting (MinCl empty where no trial moved), Markdown and LaTeX one per method,
    backend and noise level: the paper's protocol's columns (`PAPER_COLUMNS`), then those
    (`HARDWARE_COLUMNS`) of every safety-layer setting some row has (`GROUP_TITLES`
    order)."""
    fields = "method backend protocol repair sensor_noise trials refused protective_stops".split()
    fields += ["success_rate", "collision_rate", "min_clearance_p5", "executed", *INTERVAL_FIELDS]
    mincl = "min_clearance_p5"
    table_csv = csv_text(
        [row | {mincl: "" if np.isnan(row[mincl]) else row[mincl]} for row in rows], fields
    )
    present = {setting_label(r) for r in rows}
    groups = [("paper", PAPER_COLUMNS)]
    groups += [(s, HARDWARE_COLUMNS) for s in list(GROUP_TITLES)[1:] if s in present]
    wide: dict[tuple[str, str, str], dict[str, dict[str, Any]]] = {}
    for row in rows:
        wide.setdefault((row["method"], row["backend"], row["sensor_noise"]), {})[
            setting_label(row)
        ] = row
    body = [
        [METHODS[key[0]].label, *key[1:]]
        + [_cell(wide[key].get(g), k) for g, columns in groups for k, _ in columns]
        for key in sorted(wide, key=lambda k: (TABLE_ORDER.index(k[0]), *k[1:]))
    ]
    header = ["Method", "Backend", "Noise"]
    header += [f"{GROUP_TITLES[g]}: {label}" for g, columns in groups for _, label in columns]
    caption = f"{HARDWARE_CAPTION} ({preset} preset policies)"
    markdown = markdown_table(f"Table II: {caption}", header, body)
    markdown += f"\n{note}.\n" if note else ""
    return table_csv, markdown, _latex(caption, groups, body)


def _latex(caption: str, groups: list[tuple[str, Columns]], body: list[list[str]]) -> str:
    """Table II as LaTeX: a row of column-group titles over the column names."""
    latex_caption = caption.replace(" %", "\\,\\%").replace("pi rad/s", "$\\pi$ rad/s")
    latex_caption = latex_caption.replace("s^2", "s$^2$")
    titles = (f"\\multicolumn{{{len(columns)}}}{{c}}{{{GROUP_TITLES[g]}}}" for g, columns in groups)
    names = ["Method", "Backend", "Noise", *(label for _, cs in groups for _, label in cs)]
    header = [" & & & " + " & ".join(titles), " & ".join(names)]
    columns = "lll" + "c" * sum(len(columns) for _, columns in groups)
    return latex_table(latex_caption, "tab:hardware_results", columns, header, body)
