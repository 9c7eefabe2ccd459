"""The mechanism table (protocol v6, rule 7 in docs/findings/protocol.md) of a preset's runs:
the reach of a raw action against the TC range (rows of
`distgprl.experiments.mechanisms.reach_rows`, passed in) and the cells of
`distgprl.report.mechanism_shares`, each marked ✓/✗, with one verdict line per term; written
as ``mechanisms_<preset>.csv`` (`CSV_COLUMNS`) and ``.md``.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import replace
from itertools import groupby
from pathlib import Path
from typing import Any

import pandas as pd

from distgprl.config_types import EnvConfig
from distgprl.data import task_order
from distgprl.errors import UserInputError
from distgprl.methods import METHODS, TABLE_ORDER, MethodSpec
from distgprl.report.frame import csv_frame
from distgprl.report.markdown import csv_text, markdown_table, write_table_files
from distgprl.report.mechanism_shares import (
    CRITERION,
    GRADIENT_ITEMS,
    NOT_RECORDED,
    Cell,
    gradient_cells,
    mean,
    plateau_cell,
    return_cells,
)
from distgprl.report.runs import RunSelection, run_keys, select_runs
from distgprl.reward_scale import (
    MAX_GA_SHARE_OF_SUCCESS,
    MAX_IDLE_SHARE_OF_DEMO,
    demo_outcome,
    demo_task_return,
    success_task_return,
)
from distgprl.schema import evaluation_file_names


def _run_scale(folder: Path) -> dict[str, Any]:
    """A run's ``seed``, ``d_min`` (m), ``progress_weight`` and, under its recorded reward scale
    (`distgprl.reward_scale`; a field it lacks its default), a success's r_tc
    ``success_return`` and the demonstration's mean r_tc ``demo_return``."""
    document = json.loads((folder / "config.json").read_text())
    recorded = document.get("run", {}).get("config", {}).get("env", {})
    fields = ("sd_d_min", "progress_weight", "success_bonus", "collision_penalty")
    values: dict[str, Any] = {
        field: float(recorded.get(field, getattr(EnvConfig, field))) for field in fields
    }
    env = replace(EnvConfig(), **values)
    task, _, seed = run_keys(folder)
    demo = demo_task_return(env, demo_outcome(task))
    return {"seed": seed, "d_min": env.sd_d_min, "progress_weight": env.progress_weight} | {
        "success_return": success_task_return(env),
        "demo_return": demo,
    }


def _order(task: str, method: str) -> tuple[int, int, str]:
    """Tasks in the paper's order, methods in Table I's (unknown ones after)."""
    index = TABLE_ORDER.index(method) if method in TABLE_ORDER else len(TABLE_ORDER)
    return task_order(task), index, method


def _by_method(
    selection: RunSelection, uses: Callable[[MethodSpec], bool]
) -> list[tuple[tuple[str, str], list[Path]]]:
    """((task, method), its run folders, sorted) of the selected runs whose method ``uses``,
    in `_order`."""
    runs: dict[tuple[str, str], list[Path]] = {}
    for folder in sorted(selection.current):
        if uses(METHODS[folder.parent.name]):
            runs.setdefault((folder.parent.parent.name, folder.parent.name), []).append(folder)
    return sorted(runs.items(), key=lambda item: _order(*item[0]))


def mechanism_cells(root: str | Path, preset: str) -> dict[str, Any]:
    """The cells of the preset's runs under ``root`` in the tables' order: ``returns`` and
    ``plateau`` of the evaluated runs of the current configuration, ``gradients`` of the
    trained ones (`distgprl.report.runs.select_runs`); ``note``: which runs were left out."""
    evaluated = select_runs(root, preset)
    trained = select_runs(root, preset, marker="done.json")
    returns, plateau, gradients = [], [], []
    for (task, method), folders in _by_method(evaluated, lambda spec: spec.distance_rewards):
        for policy in ("final", "best"):
            paths = [folder / evaluation_file_names(None, policy)[0] for folder in folders]
            runs = [csv_frame(path, _run_scale(path.parent)) for path in paths if path.exists()]
            if runs:
                keys = {"task": task, "method": method, "where": policy}
                episodes = pd.concat(runs, ignore_index=True)
                returns += return_cells(keys, episodes)
                plateau += [cell] if (cell := plateau_cell(keys, episodes)) else []
    plateau.sort(key=lambda cell: (_order(cell["task"], cell["method"]), cell["where"]))
    regularised = _by_method(trained, lambda s: s.trainable and (s.similarity_loss or s.hap_prior))
    for (task, method), folders in regularised:
        curves = [csv_frame(folder / "progress.csv", {}) for folder in folders]
        gradients += gradient_cells(task, method, curves)
    note = ". ".join(dict.fromkeys(part for part in (evaluated.note(), trained.note()) if part))
    return {"returns": returns, "gradients": gradients, "plateau": plateau, "note": note}


DESCRIPTION = (
    "the mechanism table (FINDINGS Protocol v6 rule 7): reach against the TC range, shaping "
    "shares of the return, regulariser shares of the actor gradient (distgprl.report.mechanisms)"
)


def write_mechanisms(
    root: str | Path, preset: str, out_dir: str | Path, reach: Sequence[Mapping[str, Any]]
) -> tuple[list[Path], list[str]]:
    """Write ``<out_dir>/mechanisms_<preset>.csv`` (with its sidecar, `write_table_files`)
    and ``.md``; returns (the paths written, the one-line verdicts per term)."""
    cells = mechanism_cells(root, preset)
    if not (reach or cells["returns"] or cells["gradients"]):
        raise UserInputError(f"{Path(root) / preset}: no runs to tabulate; run a sweep first")
    csv, markdown, verdicts = mechanism_texts(preset, reach, **cells)
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
``seeds``) or ``reward_scale`` (protocol v8 rule 1 measured: ``item`` ``ga_of_success`` (a) or
``idle_of_demo`` (b), ``where`` the policy, ``episodes`` the ratios' count, ``share_max``
judged against the rule's bound). ``meets_criterion``: ``yes``/``no`` (≥ 5 %; rule 1: the
largest within its bound), ``not recorded``, ``inactive``, ``n/a``."""

RULE_ONE = {
    "ga_of_success": MAX_GA_SHARE_OF_SUCCESS,
    "idle_of_demo": MAX_IDLE_SHARE_OF_DEMO,
}
"""Rule 1's measured ratios (`distgprl.report.mechanism_shares.plateau_cell`) -> bound."""

MARKS = {"yes": " ✓", "no": " ✗"}
TERM_LABELS = {
    "r_sd": "r_sd / r_tc",
    "r_ga": "λ_ga r_ga / r_tc",
    "l_sim": "λ_sim L_sim / Q",
    "l_hap": "λ_hap L_hap / Q (all samples)",
    "l_hap_active": "λ_hap L_hap / Q outside C_safe",
    "ga_of_success": "Rule 1 (a), λ_ga Σ r_ga of an episode over a success's r_tc",
    "idle_of_demo": "Rule 1 (b), an idle episode's return over the demonstration's mean r_tc",
}


def _csv_cell(value: Any) -> Any:
    if isinstance(value, float):
        return f"{value:.6g}"
    return "" if value is None else value


def _percent(value: float | None) -> str:
    return "–" if value is None else f"{100 * value:.1f} %"


def _label(method: str) -> str:
    return METHODS[method].label if method in METHODS else method


def _covers(rows: Sequence[Mapping[str, Any]]) -> str:
    """``yes`` where a method and task's smallest one-episode reach is at least the TC range
    on x and on y (up to rounding, 1e-9 m), ``no`` otherwise, ``n/a`` for reach in ProMP
    weight units."""
    if any(row["kind"] == "ProMP weight" for row in rows):
        return "n/a"
    planar = [row for row in rows if row["axis"] in ("x", "y")]
    ok = all(row["episode_min_m"] >= row["tc_range_m"] - 1e-9 for row in planar)
    return "yes" if ok and planar else "no"


def _reach(reach: Iterable[Mapping[str, Any]]) -> list[Cell]:
    """The reach rows in `_order`, each with ``item`` (its axis) and `_covers` of its
    method and task's."""
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for row in reach:
        groups.setdefault((row["task"], row["method"]), []).append(row)
    return [
        {**row, "section": "reach", "item": row["axis"], "covers_tc_range": _covers(group)}
        for key, group in sorted(groups.items(), key=lambda item: _order(*item[0]))
        for row in group
    ]


def _rule_one(plateau: Iterable[Cell]) -> list[Cell]:
    """The ``reward_scale`` rows: per plateau cell and rule 1 ratio it has, the ratios' mean
    and largest, judged against the bound."""
    return [
        {**cell, "section": "reward_scale", "item": item, "episodes": len(cell[item])}
        | {"share_mean": mean(cell[item]), "share_max": max(cell[item])}
        | {"meets_criterion": "yes" if max(cell[item]) <= bound else "no"}
        for cell in plateau
        for item, bound in RULE_ONE.items()
        if len(cell[item])
    ]


def _rows(cells: Iterable[Cell]) -> Iterator[tuple[list[str], dict[str, Cell]]]:
    """Per (task, method, where) of consecutive ``cells``: the table row's first cells
    (task, method) and {item: cell}."""
    for (task, method, _), group in groupby(cells, lambda c: (c["task"], c["method"], c["where"])):
        yield [task.upper(), _label(method)], {cell["item"]: cell for cell in group}


def _spans(axes: Sequence[Mapping[str, Any]], span: str) -> str:
    """The ``span`` (``one_step`` or ``episode``) reach's min–max (m) per axis of ``axes``."""
    return " / ".join(f"{row[f'{span}_min_m']:.3f}–{row[f'{span}_max_m']:.3f}" for row in axes)


def _reach_rows(reach: Sequence[Cell]) -> Iterator[list[str]]:
    for _, group in groupby(reach, lambda row: (row["task"], row["method"])):
        axes = sorted(group, key=lambda row: "xyz".index(row["axis"]))
        kind, gate, covers = axes[0]["kind"], axes[0].get("gate_max"), axes[0]["covers_tc_range"]
        yield [
            axes[0]["task"].upper(),
            _label(axes[0]["method"]),
            kind if gate is None else f"{kind}, × gate ≤ {gate:.2f}",
            " / ".join(f"{row['tc_range_m']:.3f}" for row in axes),
            *(_spans(axes, span) for span in ("one_step", "episode")),
            covers + MARKS.get(covers, ""),
        ]


def _share_text(cell: Cell | None) -> str:
    """A share cell's text: its mean as a percentage (a return share's with its median),
    marked; else its verdict (a return share without a ratio: none within d_min); — where
    the method has no such term."""
    if cell is None:
        return "—"
    verdict, share = cell["meets_criterion"], cell["share_mean"]
    if share is None:
        return "– (no episode within d_min)" if verdict == "n/a" and "recorded" in cell else verdict
    median = f" (median {_percent(cell['share_median'])})" if "share_median" in cell else ""
    return _percent(share) + median + MARKS.get(verdict, "")


def _return_rows(returns: Sequence[Cell]) -> Iterator[list[str]]:
    for first, terms in _rows(returns):
        cell = terms["r_sd"]
        recorded = cell["recorded"] > 0
        yield first + [
            cell["where"],
            str(cell["seeds"]),
            f"{cell['episodes_within_d_min']} of {cell['episodes']}" if recorded else NOT_RECORDED,
            str(cell["episodes_zero_tc"]) if recorded else "",
            *(_share_text(terms[term]) for term in ("r_sd", "r_ga")),
        ]


def _gradient_rows(gradients: Sequence[Cell]) -> Iterator[list[str]]:
    for first, items in _rows(gradients):
        cell = next(iter(items.values()))
        fraction = items["l_hap_active"]["active_fraction"] if "l_hap_active" in items else None
        yield first + [
            f"{cell['where']} ({cell['step']})",
            str(cell["seeds"]),
            *(_share_text(items.get(item)) for item in GRADIENT_ITEMS),
            "—" if fraction is None else _percent(fraction),
        ]


def _bounded(ratios: Sequence[float], bound: float) -> str:
    """``max 2.1 % (mean 0.4 %) ✓``: the largest and the mean of ``ratios``, marked against
    rule 1's ``bound``; – without ratios."""
    if not len(ratios):
        return "–"
    mark = MARKS["yes" if max(ratios) <= bound else "no"]
    return f"max {_percent(max(ratios))} (mean {_percent(mean(ratios))}){mark}"


def _plateau_rows(plateau: Sequence[Cell]) -> Iterator[list[str]]:
    for cell in plateau:
        yield [
            cell["task"].upper(),
            _label(cell["method"]),
            cell["where"],
            str(cell["seeds"]),
            f"{cell['idle']} of {cell['episodes']} ({_percent(cell['idle'] / cell['episodes'])})",
            "–" if cell["mean_ga"] is None else f"{cell['mean_ga']:.3f}",
            *(_bounded(cell[item], bound) for item, bound in RULE_ONE.items()),
        ]


OTHER_VERDICTS = {"n/a": "no episode within d_min", "inactive": "inactive (inside C_safe)"}
"""How a verdict line names the cells the criterion does not judge."""


def _verdict(label: str, cells: list[Cell], name: str) -> str:
    """One line: how many ``cells`` meet the criterion, which do not (each ``name`` filled in
    from the cell; at most 4 named, else their count and range), and the term's verdict."""
    no = [(name.format_map(c), c["share_mean"]) for c in cells if c["meets_criterion"] == "no"]
    other = Counter(cell["meets_criterion"] for cell in cells)
    decided = other.pop("yes", 0) + other.pop("no", 0)
    if not decided:
        line = f"{label}: undecided (no cell where it acts and is recorded)"
    else:
        outcome = "does not meet the criterion" if no else "meets the criterion"
        line = f"{label}: {outcome} — ≥ {100 * CRITERION:.0f} % in {decided - len(no)} of "
        line += f"{decided} cells"
    if len(no) > 4:
        (low, low_value), *_, (high, high_value) = sorted(no, key=lambda item: item[1] or 0.0)
        line += (
            f"; below in {len(no)} cells, from {low} {_percent(low_value)} "
            f"to {high} {_percent(high_value)}"
        )
    elif no:
        line += "; below: " + ", ".join(f"{name} {_percent(value)}" for name, value in no)
    if other:
        line += "; " + ", ".join(
            f"{OTHER_VERDICTS.get(verdict, verdict)}: {count}"
            for verdict, count in sorted(other.items())
        )
    return line + "."


def _verdict_lines(
    reach: Sequence[Cell], returns: Sequence[Cell], gradients: Sequence[Cell], scale: Sequence[Cell]
) -> list[str]:
    """One line per mechanism: reach, r_sd, lambda_ga r_ga, lambda_sim L_sim, lambda_hap L_hap
    (outside C_safe) and rule 1's two ratios."""
    lines = []
    covers = {(r["task"], r["method"]): r["covers_tc_range"] for r in reach}
    judged = [key for key, value in covers.items() if value != "n/a"]
    if judged:
        missing = [f"{task}/{method}" for task, method in judged if covers[task, method] == "no"]
        line = (
            f"Reach: the one-episode reach covers the TC range on x and y for "
            f"{sum(covers[key] == 'yes' for key in judged)} of {len(judged)} method–task pairs"
        )
        lines.append(line + (f"; not for {', '.join(missing)}." if missing else "."))
    for term in ("r_sd", "r_ga"):
        if cells := [c for c in returns if c["item"] == term]:
            label = f"{TERM_LABELS[term]} (episodes within d_min)"
            lines.append(_verdict(label, cells, "{task}/{method} ({where})"))
    for item in ("l_sim", "l_hap_active"):
        if cells := [c for c in gradients if c["item"] == item]:
            lines.append(_verdict(TERM_LABELS[item], cells, "{task}/{method} {where}"))
    for item, bound in RULE_ONE.items():
        if cells := [c for c in scale if c["item"] == item]:
            within = sum(c["meets_criterion"] == "yes" for c in cells)
            top = max(cells, key=lambda c: c["share_max"])
            lines.append(
                f"{TERM_LABELS[item]}, measured on the policies' evaluation episodes: within "
                f"{100 * bound:.0f} % in {within} of {len(cells)} cells; largest "
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

SECTIONS = (
    (
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
        "### Shaping shares of the return",
        ["Task", "Method", "Policy", "Seeds", "Episodes within d_min", "r_tc = 0 (left out)"]
        + ["\\|Σ r_sd\\| / \\|Σ r_tc\\| mean (median)"]
        + ["\\|Σ λ_ga r_ga\\| / \\|Σ r_tc\\| mean (median)"],
        _return_rows,
        "Per episode |Σ r_sd| / |Σ r_tc| and |Σ λ_ga r_ga| / |Σ r_tc| (the evaluation rows' "
        "return_sd, return_ga, return_tc), over the episodes whose minimum clearance is below "
        "the run's d_min, pooled over seeds; episodes with Σ r_tc = 0 have no ratio and are "
        f'left out (counted). "{NOT_RECORDED}": evaluation files written before those '
        "columns.",
    ),
    (
        "### Regulariser shares of the actor gradient",
        ["Task", "Method", "Point (step)", "Seeds", *(TERM_LABELS[item] for item in GRADIENT_ITEMS)]
        + ["Samples outside C_safe"],
        _gradient_rows,
        "grad_sim / grad_q, grad_hap / grad_q and grad_hap_active / grad_q of progress.csv "
        "(mean per-sample gradient norms on the actor's output, "
        "`RegularisedSAC.actor_loss_gradient_norms`), at the first, middle and last "
        "learning-curve points with a gradient, mean over seeds; only the outside-C_safe "
        "share is judged.",
    ),
    (
        "### The r_ga plateau and rule 1's ratios, measured",
        ["Task", "Method", "Policy", "Seeds", "Idle episodes", "Mean λ_ga r_ga in them"]
        + [f"(a) λ_ga Σ r_ga / a success's r_tc (≤ {100 * MAX_GA_SHARE_OF_SUCCESS:.0f} %)"]
        + [f"(b) idle return / the demo's mean r_tc (≤ {100 * MAX_IDLE_SHARE_OF_DEMO:.0f} %)"],
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
"""The Markdown's tables in order: (title, header, its rows from its cells, the definition
written under it); the plateau's only where there are plateau cells."""


def mechanism_texts(
    preset: str,
    reach: Sequence[Mapping[str, Any]],
    returns: Sequence[Cell] = (),
    gradients: Sequence[Cell] = (),
    plateau: Sequence[Cell] = (),
    note: str = "",
) -> tuple[str, str, list[str]]:
    """(CSV text, Markdown text, verdict lines) of the ``reach`` rows and the cells of
    `mechanism_cells` (in its order); ``note`` closes the Markdown."""
    reached, scale = _reach(reach), _rule_one(plateau)
    verdicts = _verdict_lines(reached, returns, gradients, scale)
    markdown = f"## Mechanism table ({preset})\n\n{INTRO}\n\n"
    parts = (reached, returns, gradients, plateau)[: 4 if plateau else 3]
    for (title, header, rows, definition), cells in zip(SECTIONS, parts, strict=False):
        markdown += f"{markdown_table(title, header, rows(cells))}\n{definition}\n\n"
    lines = ["", "### Verdicts", "", *(f"- {line}" for line in verdicts)]
    lines += ["", note + "."] if note else []
    csv_rows = [
        {k: _csv_cell(v) for k, v in row.items()}
        for row in [*reached, *returns, *gradients, *scale]
    ]
    return csv_text(csv_rows, CSV_COLUMNS), markdown + "\n".join(lines) + "\n", verdicts
