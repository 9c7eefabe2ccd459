"""The mechanism table of a preset's runs (docs/findings/protocol.md, rule 7; protocol
rule 1's ratios), each judged, with a verdict line per term.
A cell: a dict of the `CSV_COLUMNS` (shares as fractions, None where none) and the values
behind them."""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from itertools import groupby
from operator import itemgetter
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from distgprl import reward_scale
from distgprl.config_types import EnvConfig
from distgprl.data import task_order
from distgprl.errors import UserInputError
from distgprl.methods import METHODS, TABLE_ORDER, MethodSpec
from distgprl.report.frame import csv_frame
from distgprl.report.markdown import csv_text, markdown_table, write_table_files
from distgprl.report.runs import RunSelection, run_keys, select_runs
from distgprl.schema import evaluation_file_names

CRITERION = 0.05
"""The pre-registered share (rule 7) a shaping term's return or a regulariser's gradient meets."""

NOT_RECORDED = "not recorded"
"""The verdict of a cell whose result files predate the columns it needs."""

POINTS = ("first", "middle", "last")
"""The learning-curve points of the gradient shares."""

RETURN_TERMS = {"r_ga": "return_ga", "r_sd": "return_sd"}
"""Shaping term -> its evaluation column (``return_ga`` holds lambda_ga r_ga), in row order."""

GRADIENT_ITEMS = {"l_sim": "grad_sim", "l_hap": "grad_hap", "l_hap_active": "grad_hap_active"}
"""Regulariser item (``l_hap_active``: outside C_safe) -> its ``progress.csv`` column."""

ZERO_TC = 1e-9
"""|Σ r_tc| at most this counts as Σ r_tc = 0 (no ratio): rounding residues are ~1e-15."""

IDLE_PROGRESS = 0.05
"""An episode without success or collision is idle below this share of the progress weight."""

RULE_ONE = {
    "ga_of_success": reward_scale.MAX_GA_SHARE_OF_SUCCESS,
    "idle_of_demo": reward_scale.MAX_IDLE_SHARE_OF_DEMO,
}
"""Rule 1's ratios, measured (`rule_one_cells`) -> their bound."""

Cell = dict[str, Any]
Columns = Callable[[Cell, dict[str, Cell]], list[str]]
"""A section's Markdown columns after Task and Method from a row's first cell and its cells."""


def _columns(frame: pd.DataFrame, columns: Iterable[str]) -> pd.DataFrame:
    """``frame`` with ``columns``, NaN where it lacks one."""
    return frame.assign(**{column: frame.get(column, np.nan) for column in columns})


def _mean(values: Sequence[float] | np.ndarray) -> float | None:
    return float(np.mean(values)) if len(values) else None


def _judged(share: float) -> str:
    return "yes" if share >= CRITERION else "no"


def return_cells(keys: Cell, episodes: pd.DataFrame) -> list[Cell]:
    """The r_ga and r_sd cells of one policy (``keys``: task, method, where) from its runs'
    evaluation ``episodes`` (with ``seed``, ``d_min`` in m), pooled over the runs recording the
    return's parts: ``shares`` per episode |Σ term| / |Σ r_tc| within d_min, Σ r_tc ≠ 0."""
    needed = ["return_tc", *RETURN_TERMS.values()]
    parts = _columns(episodes, needed)
    complete = parts[needed].notna().all(axis=1)
    recorded = parts[complete.groupby(parts["seed"]).transform("all")]
    within = recorded["min_clearance"] < recorded["d_min"]
    paid = within & (recorded["return_tc"].abs() > ZERO_TC)
    counts = {"seeds": episodes["seed"].nunique(), "recorded": recorded["seed"].nunique()}
    counts |= {"episodes": len(recorded), "episodes_within_d_min": int(within.sum())}
    counts["episodes_zero_tc"] = int(within.sum() - paid.sum())
    cells = []
    for term, column in RETURN_TERMS.items():
        shares = (recorded[column].abs() / recorded["return_tc"].abs())[paid].to_numpy()
        share = _mean(shares)
        verdict = "n/a" if share is None else _judged(share)
        cells.append(
            {"section": "return_share", **keys, **counts, "item": term, "shares": shares}
            | {"share_mean": share, "share_median": None if share is None else np.median(shares)}
            | {"meets_criterion": verdict if counts["recorded"] else NOT_RECORDED}
        )
    return cells


def rule_one_cells(keys: Cell, episodes: pd.DataFrame) -> list[Cell]:
    """Rule 1's ratios over the ``episodes`` recording r_tc (as `return_cells`', with the
    `_run_scale` columns): ``ga_of_success`` per episode, ``idle_of_demo`` per idle one, each
    with the ``idle`` count and their mean lambda_ga r_ga ``mean_ga``."""
    rows = _columns(episodes, ["return_tc", "return_sd", "return_ga"])
    rows = rows[rows["return_tc"].notna()]
    ga = rows["return_ga"].fillna(0.0)
    done = rows["success"].round().astype(bool) | rows["collision"].round().astype(bool)
    idle = ~done & (rows["return_tc"] < IDLE_PROGRESS * rows["progress_weight"])
    whole = rows["return_tc"] + rows["return_sd"].fillna(0.0) + ga
    ratios = {"ga_of_success": ga / rows["success_return"]}
    ratios["idle_of_demo"] = (whole / rows["demo_return"])[idle]
    plateau: Cell = {"seeds": rows["seed"].nunique(), "idle": int(idle.sum())}
    plateau["mean_ga"] = _mean(ga[idle].to_numpy())
    return [
        {"section": "reward_scale", **keys, **plateau, "item": item, "episodes": len(values)}
        | {"share_mean": _mean(values.to_numpy()), "share_max": values.max()}
        | {"meets_criterion": "yes" if values.max() <= RULE_ONE[item] else "no"}
        for item, values in ratios.items()
        if len(values)
    ]


def gradient_points(curve: pd.DataFrame) -> pd.DataFrame:
    """The first, middle (row (n - 1) // 2 of n) and last rows by step of a learning ``curve``
    with ``grad_q`` > 0, indexed by `POINTS`; empty if none has."""
    recorded = curve[curve["grad_q"] > 0].sort_values("step", kind="stable")
    last = len(recorded) - 1
    return recorded.iloc[[0, last // 2, last]].set_axis(POINTS) if last >= 0 else recorded


def gradient_cells(keys: Cell, curves: Sequence[pd.DataFrame]) -> list[Cell]:
    """The cells of the items one method (``keys``: task, method) uses at each of `POINTS` of
    its runs' learning ``curves``: ``shares`` grad_item / grad_q per run recording it;
    ``inactive``: no share and no run with a sample outside C_safe; ``l_hap`` not judged."""
    spec = METHODS[keys["method"]]
    used = {"l_sim": spec.similarity_loss, "l_hap": spec.hap_prior, "l_hap_active": spec.hap_prior}
    active = "hap_active_fraction"  # progress.csv: the share of samples outside C_safe
    columns = ["step", "grad_q", active, *GRADIENT_ITEMS.values()]
    points = pd.concat([gradient_points(_columns(curve, columns)) for curve in curves])
    cells = []
    for point in POINTS:
        rows = points[points.index == point]
        low, high = rows["step"].astype(int).agg(["min", "max"]) if len(rows) else ("", "")
        inactive = len(rows) == len(curves) and bool((rows[active] == 0.0).all())
        fraction = _mean(rows[active].dropna().to_numpy())
        point_keys = {"where": point, "step": str(low) if low == high else f"{low}–{high}"}
        for item in (item for item in GRADIENT_ITEMS if used[item]):
            value = rows[GRADIENT_ITEMS[item]]
            shares = (value / rows["grad_q"])[value.notna()].to_numpy()
            share, hap = _mean(shares), item == "l_hap_active"
            verdict = "inactive" if hap and inactive else NOT_RECORDED
            verdict = "n/a" if item == "l_hap" else verdict if share is None else _judged(share)
            cells.append(
                {"section": "gradient_share", **keys, "item": item, **point_keys}
                | {"seeds": len(rows), "shares": shares, "share_mean": share}
                | {"active_fraction": fraction if hap else None, "meets_criterion": verdict}
            )
    return cells


def _run_scale(folder: Path) -> dict[str, Any]:
    """A run's ``seed``, ``d_min`` (m) and, under its recorded reward scale (defaults for
    fields it lacks), ``progress_weight``, a success's r_tc and the demonstration's mean r_tc."""
    document = json.loads((folder / "config.json").read_text())
    recorded = document.get("run", {}).get("config", {}).get("env", {})
    fields = ("sd_d_min", "progress_weight", "success_bonus", "collision_penalty")
    values: dict[str, Any] = {f: float(recorded[f]) for f in fields if f in recorded}
    env = EnvConfig(**values)
    task, _, seed = run_keys(folder)
    return {
        "seed": seed,
        "d_min": env.sd_d_min,
        "progress_weight": env.progress_weight,
        "success_return": reward_scale.success_task_return(env),
        "demo_return": reward_scale.demo_task_return(env, reward_scale.demo_outcome(task)),
    }


def _order(task: str, method: str) -> tuple[int, int, str]:
    """Tasks in the paper's order, methods in Table I's (others after)."""
    index = TABLE_ORDER.index(method) if method in TABLE_ORDER else len(TABLE_ORDER)
    return task_order(task), index, method


def _by_method(
    selection: RunSelection, uses: Callable[[MethodSpec], bool]
) -> Iterator[tuple[Cell, list[Path]]]:
    """((task, method) keys, folders) of the selected runs whose method ``uses``, in `_order`."""
    folders = [folder for folder in selection.current if uses(METHODS[folder.parent.name])]
    ordered = sorted(folders, key=lambda folder: (_order(*run_keys(folder)[:2]), folder))
    for (task, method), group in groupby(ordered, lambda folder: run_keys(folder)[:2]):
        yield {"task": task, "method": method}, list(group)


def mechanism_cells(root: str | Path, preset: str) -> tuple[list[Cell], str]:
    """The cells of the preset's current runs under ``root`` in the CSV's order (return
    shares, gradient shares of the trained runs, rule 1's ratios) and a note of those left out."""
    evaluated = select_runs(root, preset)
    trained = select_runs(root, preset, marker="done.json")
    returns, scale, gradients = [], [], []
    for keys, folders in _by_method(evaluated, lambda spec: spec.distance_rewards):
        for policy in ("final", "best"):
            paths = [folder / evaluation_file_names(None, policy)[0] for folder in folders]
            runs = [csv_frame(path, _run_scale(path.parent)) for path in paths if path.exists()]
            if runs:
                episodes = pd.concat(runs, ignore_index=True)
                returns += return_cells(keys | {"where": policy}, episodes)
                scale += rule_one_cells(keys | {"where": policy}, episodes)
    scale.sort(key=lambda cell: (_order(cell["task"], cell["method"]), cell["where"]))
    for keys, folders in _by_method(
        trained, lambda s: s.trainable and (s.similarity_loss or s.hap_prior)
    ):
        gradients += gradient_cells(keys, [csv_frame(f / "progress.csv", {}) for f in folders])
    note = ". ".join(dict.fromkeys(part for part in (evaluated.note(), trained.note()) if part))
    return returns + gradients + scale, note


def write_mechanisms(
    root: str | Path, preset: str, out_dir: str | Path, reach: Sequence[Mapping[str, Any]]
) -> tuple[list[Path], list[str]]:
    """Write ``<out_dir>/mechanisms_<preset>.csv`` (with its sidecar, `write_table_files`)
    and ``.md``; returns (the paths written, the one-line verdicts per term)."""
    cells, note = mechanism_cells(root, preset)
    if not (reach or cells):
        raise UserInputError(f"{Path(root) / preset}: no runs to tabulate; run a sweep first")
    csv, markdown, verdicts = mechanism_texts(preset, reach, cells, note)
    description = (
        "the mechanism table (FINDINGS Protocol v6 rule 7): reach against the TC range, "
        "shaping shares of the return, regulariser shares of the actor gradient "
        "(distgprl.report.mechanisms)"
    )
    stem = Path(out_dir) / f"mechanisms_{preset}"
    written = write_table_files(
        stem, (".csv", ".md"), (csv, markdown), preset, description, criterion=CRITERION
    )
    return written, verdicts


CSV_COLUMNS = tuple(
    "section task method item where step kind one_step_min_m one_step_max_m episode_min_m "
    "episode_max_m tc_range_m covers_tc_range seeds episodes episodes_within_d_min "
    "episodes_zero_tc share_mean share_median share_max active_fraction meets_criterion".split()
)
"""Columns of ``mechanisms_<preset>.csv``, a row per cell: ``section`` its `SECTIONS` table,
``item`` the axis (reach, m) or the term, ``where`` the policy or learning-curve point (its RL
``step``s); ``meets_criterion`` ``yes``/``no``, ``not recorded``, ``inactive`` or ``n/a``."""

MARKS = {"yes": " ✓", "no": " ✗"}
VERDICT_LABELS = {
    "r_sd": "r_sd / r_tc (episodes within d_min)",
    "r_ga": "λ_ga r_ga / r_tc (episodes within d_min)",
    "l_sim": "λ_sim L_sim / Q",
    "l_hap_active": "λ_hap L_hap / Q outside C_safe",
    "ga_of_success": "Rule 1 (a), λ_ga Σ r_ga of an episode over a success's r_tc",
    "idle_of_demo": "Rule 1 (b), an idle episode's return over the demonstration's mean r_tc",
}
"""The judged items in the verdicts' order -> the name of their verdict line's term."""


def _percent(value: float | None) -> str:
    return "–" if value is None else f"{100 * value:.1f} %"


def _reach(reach: Iterable[Mapping[str, Any]]) -> list[Cell]:
    """The reach rows (x, y, z per task and method) in `_order` as cells; ``covers_tc_range``
    ``yes`` where the one-episode reach covers the TC range on x and y, ``n/a`` in ProMP units."""
    cells = []
    ordered = sorted(reach, key=lambda row: _order(row["task"], row["method"]))
    for _, group in groupby(ordered, itemgetter("task", "method")):
        axes = list(group)
        covered = all(row["episode_min_m"] >= row["tc_range_m"] - 1e-9 for row in axes[:2])
        covers = "n/a" if axes[0]["kind"] == "ProMP weight" else "yes" if covered else "no"
        marks = {"section": "reach", "where": None, "covers_tc_range": covers}
        cells += [{**row, "item": row["axis"], **marks} for row in axes]
    return cells


def _rows(cells: Iterable[Cell], columns: Columns) -> Iterator[list[str]]:
    """A Markdown row per (task, method, where) of consecutive ``cells``."""
    for (task, method, _), group in groupby(cells, itemgetter("task", "method", "where")):
        items = {cell["item"]: cell for cell in group}
        yield [task.upper(), METHODS[method].label, *columns(next(iter(items.values())), items)]


def _reach_columns(cell: Cell, axes: dict[str, Cell]) -> list[str]:
    kind, gate, covers = cell["kind"], cell["gate_max"], cell["covers_tc_range"]
    spans = [
        " / ".join(
            f"{row[f'{span}_min_m']:.3f}–{row[f'{span}_max_m']:.3f}" for row in axes.values()
        )
        for span in ("one_step", "episode")
    ]
    return [
        kind if gate is None else f"{kind}, × gate ≤ {gate:.2f}",
        " / ".join(f"{row['tc_range_m']:.3f}" for row in axes.values()),
        *spans,
        covers + MARKS.get(covers, ""),
    ]


def _share_text(cell: Cell | None) -> str:
    """A share's mean as a percentage, a return share's with its median, marked; else its
    verdict (a return share's ``n/a``: no episode within d_min); — where no such term acts."""
    if cell is None:
        return "—"
    verdict, share, returned = cell["meets_criterion"], cell["share_mean"], "share_median" in cell
    if share is None:
        return "– (no episode within d_min)" if verdict == "n/a" and returned else verdict
    median = f" (median {_percent(cell['share_median'])})" if returned else ""
    return _percent(share) + median + MARKS.get(verdict, "")


def _return_columns(cell: Cell, terms: dict[str, Cell]) -> list[str]:
    recorded = cell["recorded"] > 0
    return [
        cell["where"],
        str(cell["seeds"]),
        f"{cell['episodes_within_d_min']} of {cell['episodes']}" if recorded else NOT_RECORDED,
        str(cell["episodes_zero_tc"]) if recorded else "",
        *(_share_text(terms[term]) for term in ("r_sd", "r_ga")),
    ]


def _gradient_columns(cell: Cell, items: dict[str, Cell]) -> list[str]:
    fraction = items.get("l_hap_active", {}).get("active_fraction")
    return [
        f"{cell['where']} ({cell['step']})",
        str(cell["seeds"]),
        *(_share_text(items.get(item)) for item in GRADIENT_ITEMS),
        "—" if fraction is None else _percent(fraction),
    ]


def _bounded(cell: Cell | None) -> str:
    """``max 2.1 % (mean 0.4 %) ✓``: a rule 1 ratio's largest and mean, marked; – without."""
    if cell is None:
        return "–"
    maximum, average = _percent(cell["share_max"]), _percent(cell["share_mean"])
    return f"max {maximum} (mean {average}){MARKS[cell['meets_criterion']]}"


def _plateau_columns(cell: Cell, items: dict[str, Cell]) -> list[str]:
    idle, episodes = cell["idle"], cell["episodes"]
    return [
        cell["where"],
        str(cell["seeds"]),
        f"{idle} of {episodes} ({_percent(idle / episodes)})",
        "–" if cell["mean_ga"] is None else f"{cell['mean_ga']:.3f}",
        *(_bounded(items.get(item)) for item in RULE_ONE),
    ]


def _verdict(label: str, cells: Sequence[Cell], name: str) -> str:
    """One line: how many ``cells`` meet the criterion, which do not (``name`` filled in from
    the cell; more than 4: their count and range) and how many are not judged."""
    no = [cell for cell in cells if cell["meets_criterion"] == "no"]
    below = [f"{name.format_map(cell)} {_percent(cell['share_mean'])}" for cell in no]
    other = Counter(cell["meets_criterion"] for cell in cells)
    decided = other.pop("yes", 0) + other.pop("no", 0)
    outcome = "does not meet the criterion" if no else "meets the criterion"
    share = f"≥ {100 * CRITERION:.0f} %"
    line = f"{label}: {outcome} — {share} in {decided - len(no)} of {decided} cells"
    if not decided:
        line = f"{label}: undecided (no cell where it acts and is recorded)"
    if len(no) > 4:
        ranked = sorted(range(len(no)), key=lambda index: no[index]["share_mean"])
        line += f"; below in {len(no)} cells, from {below[ranked[0]]} to {below[ranked[-1]]}"
    elif no:
        line += "; below: " + ", ".join(below)
    if other:
        names = {"n/a": "no episode within d_min", "inactive": "inactive (inside C_safe)"}
        line += "; " + ", ".join(f"{names.get(v, v)}: {n}" for v, n in sorted(other.items()))
    return line + "."


def _verdict_lines(rows: Sequence[Cell]) -> list[str]:
    """One line per mechanism: reach, then each of `VERDICT_LABELS`' items."""
    reach = [row for row in rows if row["section"] == "reach"]
    judged = {(r["task"], r["method"]): r["covers_tc_range"] for r in reach}
    judged = {key: value for key, value in judged.items() if value != "n/a"}
    missing = [f"{task}/{method}" for (task, method), value in judged.items() if value == "no"]
    lines = []
    if judged:
        line = (
            "Reach: the one-episode reach covers the TC range on x and y for "
            f"{len(judged) - len(missing)} of {len(judged)} method–task pairs"
        )
        lines.append(line + (f"; not for {', '.join(missing)}." if missing else "."))
    for item, label in VERDICT_LABELS.items():
        cells = [row for row in rows if row["item"] == item]
        if cells and item in RULE_ONE:
            within = sum(cell["meets_criterion"] == "yes" for cell in cells)
            top = max(cells, key=itemgetter("share_max"))
            lines.append(
                f"{label}, measured on the policies' evaluation episodes: within "
                f"{100 * RULE_ONE[item]:.0f} % in {within} of {len(cells)} cells; largest "
                f"{_percent(top['share_max'])} ({top['task']}/{top['method']}, {top['where']})."
            )
        elif cells:
            where = "({where})" if item in RETURN_TERMS else "{where}"
            lines.append(_verdict(label, cells, "{task}/{method} " + where))
    return lines


INTRO = (
    'Whether the paper\'s mechanisms act (docs/FINDINGS.md "Protocol v6", rule 7). '
    f"Criterion, pre-registered: each shaping term ≥ {100 * CRITERION:.0f} % of |r_tc| over "
    "the evaluation episodes that pass within d_min, each regulariser's actor gradient ≥ "
    f"{100 * CRITERION:.0f} % of the Q term's at the start, middle and end of a paper-size "
    "run (L_hap: over the samples outside C_safe, where it acts). ✓/✗ mark each cell."
)


SECTIONS: tuple[tuple[str, str, list[str], Columns, str], ...] = (
    (
        "reach",
        "### Reach of a raw action in [-1, 1]",
        ["Adapts", "TC range x / y / z (m)", "One step min–max x / y / z (m)"]
        + ["One episode min–max x / y / z (m)", "Covers TC range (x, y)"],
        _reach_columns,
        "Reach: one step = action scale × the smallest and largest row sum Σ_j |S_W,ij| over "
        "the adapted via-points (1 without S); one episode = summed over the steps that adapt "
        "a via-point (1 windowed, 2 at a window overlap, 3 global). ProMP-RRL: its residual, "
        "slew-limited per 0.1 s RL step, over an episode its range (the commanded offset is "
        "the residual × the variance gate). Frozen via-points (GPRL's TC via-point) left out.",
    ),
    (
        "return_share",
        "### Shaping shares of the return",
        ["Policy", "Seeds", "Episodes within d_min", "r_tc = 0 (left out)"]
        + ["\\|Σ r_sd\\| / \\|Σ r_tc\\| mean (median)"]
        + ["\\|Σ λ_ga r_ga\\| / \\|Σ r_tc\\| mean (median)"],
        _return_columns,
        "Per episode |Σ r_sd| / |Σ r_tc| and |Σ λ_ga r_ga| / |Σ r_tc| (the evaluation rows' "
        "return_sd, return_ga, return_tc), over the episodes whose minimum clearance is below "
        "the run's d_min, pooled over seeds; episodes with Σ r_tc = 0 (to within "
        f'{ZERO_TC:g}, rounding) have no ratio and are left out (counted). "{NOT_RECORDED}": '
        "evaluation files written before those columns.",
    ),
    (
        "gradient_share",
        "### Regulariser shares of the actor gradient",
        ["Point (step)", "Seeds", "λ_sim L_sim / Q", "λ_hap L_hap / Q (all samples)"]
        + ["λ_hap L_hap / Q outside C_safe", "Samples outside C_safe"],
        _gradient_columns,
        "grad_sim / grad_q, grad_hap / grad_q and grad_hap_active / grad_q of progress.csv "
        "(mean per-sample gradient norms on the actor's output, "
        "`RegularisedSAC.actor_loss_gradient_norms`), at the first, middle and last "
        "learning-curve points with a gradient, mean over seeds; only the outside-C_safe "
        "share is judged.",
    ),
    (
        "reward_scale",
        "### The r_ga plateau and rule 1's ratios, measured",
        ["Policy", "Seeds", "Idle episodes", "Mean λ_ga r_ga in them"]
        + [f"(a) λ_ga Σ r_ga / a success's r_tc (≤ {100 * RULE_ONE['ga_of_success']:.0f} %)"]
        + [f"(b) idle return / the demo's mean r_tc (≤ {100 * RULE_ONE['idle_of_demo']:.0f} %)"],
        _plateau_columns,
        "Idle: an evaluation episode with no success, no collision and r_tc below "
        f"{100 * IDLE_PROGRESS:.0f} % of the task's progress weight — the policy did not do "
        "the task; the alignment reward it still collects is paid for moving the via-points "
        "along ∇d "
        '(docs/FINDINGS.md "The first v7 runs"). (a) and (b): protocol v8 rule 1\'s two ratios '
        "(`distgprl.reward_scale`), bounded there from the reward terms' maxima, measured here "
        "on the policies' evaluation episodes: (a) over every episode, (b) over the idle ones "
        "(return r_tc + r_sd + λ_ga r_ga, over the demonstration's mean r_tc on the evaluation "
        "TCs under the run's scale); ✓ where the largest is within the bound.",
    ),
)
"""The Markdown's tables in order: (section, title, header after Task and Method, its
columns of a row's cells, the definition under it); rule 1's only where it has cells."""


def mechanism_texts(
    preset: str, reach: Sequence[Mapping[str, Any]], cells: Sequence[Cell] = (), note: str = ""
) -> tuple[str, str, list[str]]:
    """(CSV text, Markdown text, verdict lines) of the ``reach`` rows and the ``cells`` of
    `mechanism_cells`; ``note`` closes the Markdown."""
    rows = [*_reach(reach), *cells]
    verdicts = _verdict_lines(rows)
    markdown = f"## Mechanism table ({preset})\n\n{INTRO}\n\n"
    for section, title, header, columns, definition in SECTIONS:
        part = [row for row in rows if row["section"] == section]
        if part or section != "reward_scale":
            table = markdown_table(title, ["Task", "Method", *header], _rows(part, columns))
            markdown += f"{table}\n{definition}\n\n"
    lines = ["", "### Verdicts", "", *(f"- {line}" for line in verdicts)]
    lines += ["", note + "."] if note else []
    csv_rows = [
        {key: f"{value:.6g}" if isinstance(value, float) else value for key, value in row.items()}
        for row in rows
    ]
    return csv_text(csv_rows, CSV_COLUMNS), markdown + "\n".join(lines) + "\n", verdicts
