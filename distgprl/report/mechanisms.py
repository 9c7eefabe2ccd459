"""The mechanism table of a preset's runs (protocol v6, rule 7, docs/findings/protocol.md;
v8 rule 1, docs/findings/environment-v8.md): reach against the TC range (the rows of
`distgprl.experiments.mechanisms.reach_rows`), shaping shares of the return, regulariser shares
of the actor gradient and rule 1's ratios, each judged, with a verdict line per term. A cell:
a dict of the `CSV_COLUMNS` (shares as fractions, None where none) and the values behind them,
from result CSVs as frames (`distgprl.report.frame.csv_frame`: an empty cell NaN)."""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import replace
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
"""The pre-registered share (rule 7): each shaping term ≥ 5 % of the return where it acts,
each regulariser's actor gradient ≥ 5 % of the Q term's (L_hap: outside C_safe)."""

NOT_RECORDED = "not recorded"
"""The verdict of a cell whose result files predate the columns it needs."""

POINTS = ("first", "middle", "last")
"""The learning-curve points of the gradient shares."""

RETURN_TERMS = {"r_ga": "return_ga", "r_sd": "return_sd"}
"""Shaping term -> its evaluation column (``return_ga`` holds lambda_ga r_ga), in row order."""

GRADIENT_ITEMS = {"l_sim": "grad_sim", "l_hap": "grad_hap", "l_hap_active": "grad_hap_active"}
"""Regulariser item (``l_hap_active``: L_hap over the samples outside C_safe) -> its
``progress.csv`` column, a share of ``grad_q``."""

ACTIVE = "hap_active_fraction"
"""The ``progress.csv`` column of the share of samples outside C_safe."""

ZERO_TC = 1e-9
"""|Σ r_tc| at most this counts as Σ r_tc = 0 (no ratio): an episode without net progress sums
its per-step progress terms to 0 only up to floating-point rounding (residues ~1e-15)."""

IDLE_PROGRESS = 0.05
"""An episode that neither succeeded nor collided is idle if its r_tc is below this share of
the task's progress weight."""

RULE_ONE = {
    "ga_of_success": reward_scale.MAX_GA_SHARE_OF_SUCCESS,
    "idle_of_demo": reward_scale.MAX_IDLE_SHARE_OF_DEMO,
}
"""Rule 1's ratios, measured (`rule_one_cells`) -> their bound."""

Cell = dict[str, Any]


def _columns(frame: pd.DataFrame, columns: Iterable[str]) -> pd.DataFrame:
    """``frame`` with ``columns``, NaN where it lacks one."""
    return frame.assign(**{column: frame.get(column, np.nan) for column in columns})


def _mean(values: Sequence[float] | np.ndarray) -> float | None:
    return float(np.mean(values)) if len(values) else None


def _judged(share: float) -> str:
    return "yes" if share >= CRITERION else "no"


def return_cells(keys: Cell, episodes: pd.DataFrame) -> list[Cell]:
    """The r_ga and r_sd cells of one method's policy (``keys``: task, method, where) from the
    evaluation ``episodes`` of its runs (with the run's ``seed`` and ``d_min``, m), pooled
    over the ``recorded`` runs (return parts in every row): ``shares`` the per-episode
    |Σ term| / |Σ r_tc| within d_min where Σ r_tc ≠ 0 (``n/a`` without any)."""
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
    """Rule 1's ratios over one method's policy's episodes that record r_tc (``keys`` and
    ``episodes`` as `return_cells`', with the run's scale, `_run_scale`): ``ga_of_success``
    per episode, ``idle_of_demo`` per idle one; each row with the plateau's ``idle`` count
    and their mean lambda_ga r_ga ``mean_ga``."""
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
    """The first, middle (row (n - 1) // 2 of n) and last rows by step of one run's learning
    ``curve`` that recorded the actor's gradient norms (``grad_q`` > 0: not the step-0 point),
    indexed by `POINTS`; empty if none did."""
    recorded = curve[curve["grad_q"] > 0].sort_values("step", kind="stable")
    last = len(recorded) - 1
    return recorded.iloc[[0, last // 2, last]].set_axis(POINTS) if last >= 0 else recorded


def gradient_cells(keys: Cell, curves: Sequence[pd.DataFrame]) -> list[Cell]:
    """The cells of the items one method (``keys``: task, method) uses at each of `POINTS`
    from its runs' learning ``curves``: ``shares`` grad_item / grad_q per run recording it;
    ``inactive`` where no run recorded a share and every run had no sample outside C_safe at
    the point; ``l_hap`` (all samples) reported, not judged (``n/a``)."""
    spec = METHODS[keys["method"]]
    used = {"l_sim": spec.similarity_loss, "l_hap": spec.hap_prior, "l_hap_active": spec.hap_prior}
    columns = ["step", "grad_q", ACTIVE, *GRADIENT_ITEMS.values()]
    points = pd.concat([gradient_points(_columns(curve, columns)) for curve in curves])
    cells = []
    for point in POINTS:
        rows = points[points.index == point]
        low, high = rows["step"].astype(int).agg(["min", "max"]) if len(rows) else ("", "")
        inactive = len(rows) == len(curves) and bool((rows[ACTIVE] == 0.0).all())
        fraction = _mean(rows[ACTIVE].dropna().to_numpy())
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
    """A run's ``seed``, ``d_min`` (m) and, under its recorded reward scale (a field it lacks:
    the default), ``progress_weight``, a success's r_tc and the demonstration's mean r_tc."""
    document = json.loads((folder / "config.json").read_text())
    recorded = document.get("run", {}).get("config", {}).get("env", {})
    fields = ("sd_d_min", "progress_weight", "success_bonus", "collision_penalty")
    values: dict[str, Any] = {f: float(recorded.get(f, getattr(EnvConfig, f))) for f in fields}
    env = replace(EnvConfig(), **values)
    task, _, seed = run_keys(folder)
    return {
        "seed": seed,
        "d_min": env.sd_d_min,
        "progress_weight": env.progress_weight,
        "success_return": reward_scale.success_task_return(env),
        "demo_return": reward_scale.demo_task_return(env, reward_scale.demo_outcome(task)),
    }


def _order(task: str, method: str) -> tuple[int, int, str]:
    """Tasks in the paper's order, methods in Table I's (unknown ones after)."""
    index = TABLE_ORDER.index(method) if method in TABLE_ORDER else len(TABLE_ORDER)
    return task_order(task), index, method


def _by_method(
    selection: RunSelection, uses: Callable[[MethodSpec], bool]
) -> list[tuple[Cell, list[Path]]]:
    """((task, method) keys, the run folders) of the selected runs whose method ``uses``, in
    `_order`."""
    runs: dict[tuple[str, str], list[Path]] = {}
    for folder in sorted(selection.current):
        if uses(METHODS[folder.parent.name]):
            runs.setdefault((folder.parent.parent.name, folder.parent.name), []).append(folder)
    ordered = sorted(runs.items(), key=lambda item: _order(*item[0]))
    return [({"task": task, "method": method}, folders) for (task, method), folders in ordered]


def mechanism_cells(root: str | Path, preset: str) -> tuple[list[Cell], str]:
    """The cells of the preset's runs under ``root`` in the CSV's order — return shares,
    gradient shares (of the trained runs), rule 1's ratios (`distgprl.report.runs.select_runs`:
    of the current configuration) — and a note of the runs left out."""
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


DESCRIPTION = (
    "the mechanism table (FINDINGS Protocol v6 rule 7): reach against the TC range, shaping "
    "shares of the return, regulariser shares of the actor gradient (distgprl.report.mechanisms)"
)


def write_mechanisms(
    root: str | Path, preset: str, out_dir: str | Path, reach: Sequence[Mapping[str, Any]]
) -> tuple[list[Path], list[str]]:
    """Write ``<out_dir>/mechanisms_<preset>.csv`` (with its sidecar, `write_table_files`)
    and ``.md``; returns (the paths written, the one-line verdicts per term)."""
    cells, note = mechanism_cells(root, preset)
    if not (reach or cells):
        raise UserInputError(f"{Path(root) / preset}: no runs to tabulate; run a sweep first")
    csv, markdown, verdicts = mechanism_texts(preset, reach, cells, note)
    stem = Path(out_dir) / f"mechanisms_{preset}"
    written = write_table_files(
        stem, (".csv", ".md"), (csv, markdown), preset, DESCRIPTION, criterion=CRITERION
    )
    return written, verdicts


CSV_COLUMNS = tuple(
    "section task method item where step kind one_step_min_m one_step_max_m episode_min_m "
    "episode_max_m tc_range_m covers_tc_range seeds episodes episodes_within_d_min "
    "episodes_zero_tc share_mean share_median share_max active_fraction meets_criterion".split()
)
"""Columns of ``mechanisms_<preset>.csv``. ``section``: ``reach`` (``item`` the axis; reach
in m; ``covers_tc_range`` the method and task's ``yes``/``no``/``n/a`` on x and y),
``return_share`` (``item`` ``r_sd`` or ``r_ga`` (= lambda_ga r_ga), ``where`` the policy,
shares of |r_tc| over ``episodes_within_d_min`` less ``episodes_zero_tc``) or
``gradient_share`` (``item`` ``l_sim``, ``l_hap`` or ``l_hap_active`` (outside C_safe),
``where`` the learning-curve point, ``step`` its RL step(s), the share of grad_q the mean over
``seeds``) or ``reward_scale`` (rule 1 measured: ``item`` ``ga_of_success`` (a) or
``idle_of_demo`` (b), ``where`` the policy, ``episodes`` the ratios' count, ``share_max``
judged against the rule's bound). ``meets_criterion``: ``yes``/``no`` (≥ 5 %; rule 1: the
largest within its bound), ``not recorded``, ``inactive``, ``n/a``."""

MARKS = {"yes": " ✓", "no": " ✗"}
VERDICT_LABELS = {
    "r_sd": "r_sd / r_tc (episodes within d_min)",
    "r_ga": "λ_ga r_ga / r_tc (episodes within d_min)",
    "l_sim": "λ_sim L_sim / Q",
    "l_hap_active": "λ_hap L_hap / Q outside C_safe",
    "ga_of_success": "Rule 1 (a), λ_ga Σ r_ga of an episode over a success's r_tc",
    "idle_of_demo": "Rule 1 (b), an idle episode's return over the demonstration's mean r_tc",
}
"""The name of each verdict line's term."""


def _percent(value: float | None) -> str:
    return "–" if value is None else f"{100 * value:.1f} %"


def _label(method: str) -> str:
    return METHODS[method].label if method in METHODS else method


def _reach(reach: Iterable[Mapping[str, Any]]) -> list[list[Cell]]:
    """The reach rows per method and task in `_order`, each with ``item`` (its axis) and
    ``covers_tc_range``: ``yes`` where the method and task's smallest one-episode reach is at
    least the TC range on x and on y (up to rounding, 1e-9 m), ``no`` otherwise, ``n/a`` for
    reach in ProMP weight units."""
    groups = []
    ordered = sorted(reach, key=lambda row: _order(row["task"], row["method"]))
    for _, group in groupby(ordered, itemgetter("task", "method")):
        axes = list(group)
        planar = [row for row in axes if row["axis"] in ("x", "y")]
        covered = planar and all(row["episode_min_m"] >= row["tc_range_m"] - 1e-9 for row in planar)
        covers = "yes" if covered else "no"
        if any(row["kind"] == "ProMP weight" for row in axes):
            covers = "n/a"
        marks = {"section": "reach", "covers_tc_range": covers}
        groups.append([{**row, "item": row["axis"], **marks} for row in axes])
    return groups


def _rows(cells: Iterable[Cell]) -> Iterator[tuple[list[str], dict[str, Cell]]]:
    """Per (task, method, where) of consecutive ``cells``: the row's first texts and
    {item: cell}."""
    for (task, method, where), group in groupby(cells, itemgetter("task", "method", "where")):
        yield [task.upper(), _label(method), where], {cell["item"]: cell for cell in group}


def _reach_rows(reach: Sequence[list[Cell]]) -> Iterator[list[str]]:
    for group in reach:
        axes = sorted(group, key=lambda row: "xyz".index(row["axis"]))
        first, covers = axes[0], axes[0]["covers_tc_range"]
        kind, gate = first["kind"], first.get("gate_max")
        spans = [
            " / ".join(f"{row[f'{span}_min_m']:.3f}–{row[f'{span}_max_m']:.3f}" for row in axes)
            for span in ("one_step", "episode")
        ]
        yield [
            first["task"].upper(),
            _label(first["method"]),
            kind if gate is None else f"{kind}, × gate ≤ {gate:.2f}",
            " / ".join(f"{row['tc_range_m']:.3f}" for row in axes),
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


def _return_rows(returns: Sequence[Cell]) -> Iterator[list[str]]:
    for first, terms in _rows(returns):
        cell = terms["r_sd"]
        recorded = cell["recorded"] > 0
        yield first + [
            str(cell["seeds"]),
            f"{cell['episodes_within_d_min']} of {cell['episodes']}" if recorded else NOT_RECORDED,
            str(cell["episodes_zero_tc"]) if recorded else "",
            *(_share_text(terms[term]) for term in ("r_sd", "r_ga")),
        ]


def _gradient_rows(gradients: Sequence[Cell]) -> Iterator[list[str]]:
    for (task, label, point), items in _rows(gradients):
        cell = next(iter(items.values()))
        fraction = items["l_hap_active"]["active_fraction"] if "l_hap_active" in items else None
        yield [
            task,
            label,
            f"{point} ({cell['step']})",
            str(cell["seeds"]),
            *(_share_text(items.get(item)) for item in GRADIENT_ITEMS),
            "—" if fraction is None else _percent(fraction),
        ]


def _bounded(cell: Cell | None) -> str:
    """``max 2.1 % (mean 0.4 %) ✓``: the largest and the mean of a rule 1 ratio, marked
    against its bound; – without ratios."""
    if cell is None:
        return "–"
    maximum, average = _percent(cell["share_max"]), _percent(cell["share_mean"])
    return f"max {maximum} (mean {average}){MARKS[cell['meets_criterion']]}"


def _plateau_rows(scale: Sequence[Cell]) -> Iterator[list[str]]:
    for first, items in _rows(scale):
        cell = items["ga_of_success"]
        idle = f"{cell['idle']} of {cell['episodes']} ({_percent(cell['idle'] / cell['episodes'])})"
        mean_ga = "–" if cell["mean_ga"] is None else f"{cell['mean_ga']:.3f}"
        yield first + [
            str(cell["seeds"]),
            idle,
            mean_ga,
            *(_bounded(items.get(item)) for item in RULE_ONE),
        ]


OTHER_VERDICTS = {"n/a": "no episode within d_min", "inactive": "inactive (inside C_safe)"}
"""How a verdict line names the cells the criterion does not judge."""


def _verdict(label: str, cells: Sequence[Cell], name: str) -> str:
    """One line: how many ``cells`` meet the criterion, which do not (``name`` filled in from
    the cell; more than 4: their count and range) and how many are not judged."""
    no = [
        (f"{name.format_map(cell)} {_percent(cell['share_mean'])}", cell["share_mean"])
        for cell in cells
        if cell["meets_criterion"] == "no"
    ]
    other = Counter(cell["meets_criterion"] for cell in cells)
    decided = other.pop("yes", 0) + other.pop("no", 0)
    if decided:
        outcome = "does not meet the criterion" if no else "meets the criterion"
        line = f"{label}: {outcome} — ≥ {100 * CRITERION:.0f} % in {decided - len(no)} of "
        line += f"{decided} cells"
    else:
        line = f"{label}: undecided (no cell where it acts and is recorded)"
    if len(no) > 4:
        (low, _), *_, (high, _) = sorted(no, key=lambda pair: pair[1])
        line += f"; below in {len(no)} cells, from {low} to {high}"
    elif no:
        line += "; below: " + ", ".join(text for text, _ in no)
    if other:
        counts = (f"{OTHER_VERDICTS.get(v, v)}: {n}" for v, n in sorted(other.items()))
        line += "; " + ", ".join(counts)
    return line + "."


def _verdict_lines(reach: Sequence[list[Cell]], cells: Sequence[Cell]) -> list[str]:
    """One line per mechanism: reach, r_sd, lambda_ga r_ga, lambda_sim L_sim, lambda_hap L_hap
    (outside C_safe) and rule 1's two ratios, from the `_reach` groups and the other cells."""
    lines = []
    covers = {(g[0]["task"], g[0]["method"]): g[0]["covers_tc_range"] for g in reach}
    if pairs := [key for key, value in covers.items() if value != "n/a"]:
        missing = [f"{task}/{method}" for task, method in pairs if covers[task, method] == "no"]
        line = (
            f"Reach: the one-episode reach covers the TC range on x and y for "
            f"{sum(covers[key] == 'yes' for key in pairs)} of {len(pairs)} method–task pairs"
        )
        lines.append(line + (f"; not for {', '.join(missing)}." if missing else "."))
    for item in ("r_sd", "r_ga", "l_sim", "l_hap_active"):
        if judged := [cell for cell in cells if cell["item"] == item]:
            where = "({where})" if item in RETURN_TERMS else "{where}"
            lines.append(_verdict(VERDICT_LABELS[item], judged, "{task}/{method} " + where))
    for item, bound in RULE_ONE.items():
        if judged := [cell for cell in cells if cell["item"] == item]:
            within = sum(cell["meets_criterion"] == "yes" for cell in judged)
            top = max(judged, key=itemgetter("share_max"))
            lines.append(
                f"{VERDICT_LABELS[item]}, measured on the policies' evaluation episodes: within "
                f"{100 * bound:.0f} % in {within} of {len(judged)} cells; largest "
                f"{_percent(top['share_max'])} ({top['task']}/{top['method']}, {top['where']})."
            )
    return lines


INTRO = (
    'Whether the paper\'s mechanisms act (docs/FINDINGS.md "Protocol v6", rule 7). '
    f"Criterion, pre-registered: each shaping term ≥ {100 * CRITERION:.0f} % of |r_tc| over "
    "the evaluation episodes that pass within d_min, each regulariser's actor gradient ≥ "
    f"{100 * CRITERION:.0f} % of the Q term's at the start, middle and end of a paper-size "
    "run (L_hap: over the samples outside C_safe, where it acts). ✓/✗ mark each cell."
)

Section = tuple[str, str, list[str], Callable[[Any], Iterator[list[str]]], str]

SECTIONS: tuple[Section, ...] = (
    (
        "reach",
        "### Reach of a raw action in [-1, 1]",
        ["Task", "Method", "Adapts", "TC range x / y / z (m)", "One step min–max x / y / z (m)"]
        + ["One episode min–max x / y / z (m)", "Covers TC range (x, y)"],
        _reach_rows,
        "Reach: one step = action scale × the smallest and largest row sum Σ_j |S_W,ij| over "
        "the adapted via-points (1 without S); one episode = summed over the steps that adapt "
        "a via-point (1 windowed, 2 at a window overlap, 3 global). ProMP-RRL: its residual, "
        "slew-limited per 0.1 s RL step, over an episode its range (the commanded offset is "
        "the residual × the variance gate). Frozen via-points (GPRL's TC via-point) left out.",
    ),
    (
        "return_share",
        "### Shaping shares of the return",
        ["Task", "Method", "Policy", "Seeds", "Episodes within d_min", "r_tc = 0 (left out)"]
        + ["\\|Σ r_sd\\| / \\|Σ r_tc\\| mean (median)"]
        + ["\\|Σ λ_ga r_ga\\| / \\|Σ r_tc\\| mean (median)"],
        _return_rows,
        "Per episode |Σ r_sd| / |Σ r_tc| and |Σ λ_ga r_ga| / |Σ r_tc| (the evaluation rows' "
        "return_sd, return_ga, return_tc), over the episodes whose minimum clearance is below "
        "the run's d_min, pooled over seeds; episodes with Σ r_tc = 0 (to within "
        f'{ZERO_TC:g}, rounding) have no ratio and are left out (counted). "{NOT_RECORDED}": '
        "evaluation files written before those "
        "columns.",
    ),
    (
        "gradient_share",
        "### Regulariser shares of the actor gradient",
        [
            "Task",
            "Method",
            "Point (step)",
            "Seeds",
            "λ_sim L_sim / Q",
            "λ_hap L_hap / Q (all samples)",
        ]
        + ["λ_hap L_hap / Q outside C_safe", "Samples outside C_safe"],
        _gradient_rows,
        "grad_sim / grad_q, grad_hap / grad_q and grad_hap_active / grad_q of progress.csv "
        "(mean per-sample gradient norms on the actor's output, "
        "`RegularisedSAC.actor_loss_gradient_norms`), at the first, middle and last "
        "learning-curve points with a gradient, mean over seeds; only the outside-C_safe "
        "share is judged.",
    ),
    (
        "reward_scale",
        "### The r_ga plateau and rule 1's ratios, measured",
        ["Task", "Method", "Policy", "Seeds", "Idle episodes", "Mean λ_ga r_ga in them"]
        + [f"(a) λ_ga Σ r_ga / a success's r_tc (≤ {100 * RULE_ONE['ga_of_success']:.0f} %)"]
        + [f"(b) idle return / the demo's mean r_tc (≤ {100 * RULE_ONE['idle_of_demo']:.0f} %)"],
        _plateau_rows,
        "Idle: an evaluation episode with no success, no collision and r_tc below 5 % of the "
        "task's progress weight — the policy did not do the task; the alignment reward it "
        "still collects is paid for moving the via-points along ∇d "
        '(docs/FINDINGS.md "The first v7 runs"). (a) and (b): protocol v8 rule 1\'s two ratios '
        "(`distgprl.reward_scale`), bounded there from the reward terms' maxima, measured here "
        "on the policies' evaluation episodes: (a) over every episode, (b) over the idle ones "
        "(return r_tc + r_sd + λ_ga r_ga, over the demonstration's mean r_tc on the evaluation "
        "TCs under the run's scale); ✓ where the largest is within the bound.",
    ),
)
"""The Markdown's tables in order: (the cells' section, title, header, its rows from those
cells, the definition written under it); rule 1's only where it has cells."""


def mechanism_texts(
    preset: str, reach: Sequence[Mapping[str, Any]], cells: Sequence[Cell] = (), note: str = ""
) -> tuple[str, str, list[str]]:
    """(CSV text, Markdown text, verdict lines) of the ``reach`` rows and the ``cells`` of
    `mechanism_cells`; ``note`` closes the Markdown."""
    reached = _reach(reach)
    verdicts = _verdict_lines(reached, cells)
    markdown = f"## Mechanism table ({preset})\n\n{INTRO}\n\n"
    for section, title, header, rows, definition in SECTIONS:
        part = reached if section == "reach" else [c for c in cells if c["section"] == section]
        if part or section != "reward_scale":
            markdown += f"{markdown_table(title, header, rows(part))}\n{definition}\n\n"
    lines = ["", "### Verdicts", "", *(f"- {line}" for line in verdicts)]
    lines += ["", note + "."] if note else []
    csv_rows = [
        {key: f"{value:.6g}" if isinstance(value, float) else value for key, value in row.items()}
        for row in [*(row for group in reached for row in group), *cells]
    ]
    return csv_text(csv_rows, CSV_COLUMNS), markdown + "\n".join(lines) + "\n", verdicts
