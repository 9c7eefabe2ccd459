"""The mechanism table (protocol v6, rule 7 in docs/findings/protocol.md) of a preset's runs,
in three parts — the reach of a raw action against the TC range (rows of
`distgprl.experiments.mechanisms.reach_rows`, passed in), the shaping shares of the return and
the regulariser shares of the actor gradient (the cells of `distgprl.report.mechanism_shares`),
each share marked ✓/✗ against the pre-registered `CRITERION` — with a one-line verdict per term
(`mechanism_texts` returns them). Writes ``mechanisms_<preset>.csv`` (`CSV_COLUMNS`) and ``.md``
(`mechanism_texts`, which states each part's definition under its table).
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import asdict, replace
from itertools import groupby
from pathlib import Path
from typing import Any

from distgprl.config_types import EnvConfig
from distgprl.data import task_order
from distgprl.errors import UserInputError
from distgprl.methods import METHODS, TABLE_ORDER, MethodSpec
from distgprl.report.markdown import csv_text, markdown_table, write_table_files
from distgprl.report.mechanism_shares import (
    CRITERION,
    GRADIENT_ITEMS,
    NOT_RECORDED,
    POINTS,
    GradientCell,
    MechanismTable,
    PlateauCell,
    ReturnCell,
    TaskReturns,
    gradient_cells,
    plateau_cell,
    return_cells,
)
from distgprl.report.runs import select_runs
from distgprl.reward_scale import (
    MAX_GA_SHARE_OF_SUCCESS,
    MAX_IDLE_SHARE_OF_DEMO,
    demo_outcome,
    demo_task_return,
    success_task_return,
)
from distgprl.schema import evaluation_file_names, read_csv


def _env(folder: Path, field: str) -> float:
    """An `EnvConfig` field of the run's recorded config (its default if absent)."""
    document = json.loads((folder / "config.json").read_text())
    env = document.get("run", {}).get("config", {}).get("env", {})
    return float(env.get(field, getattr(EnvConfig, field)))


def _task_returns(folder: Path, task: str) -> TaskReturns:
    """The run's `TaskReturns` from its recorded reward scale (protocol v8, rule 1's terms:
    `distgprl.reward_scale`) and the task's committed demonstration outcome."""
    env = replace(
        EnvConfig(),
        progress_weight=_env(folder, "progress_weight"),
        success_bonus=_env(folder, "success_bonus"),
        collision_penalty=_env(folder, "collision_penalty"),
    )
    demo = demo_task_return(env, demo_outcome(task))
    return TaskReturns(env.progress_weight, success_task_return(env), demo)


def _by_run(
    folders: Iterable[Path], uses: Callable[[MethodSpec], bool]
) -> dict[tuple[str, str], list[Path]]:
    """{(task, method): its run folders, sorted} of the ``folders`` whose method ``uses``,
    sorted by (task, method)."""
    runs = sorted((f.parent.parent.name, f.parent.name, f) for f in folders)
    used = [run for run in runs if uses(METHODS[run[1]])]
    return {key: [run[2] for run in group] for key, group in groupby(used, lambda run: run[:2])}


def mechanism_table(
    root: str | Path, preset: str, reach: Sequence[Mapping[str, Any]]
) -> MechanismTable:
    """The `MechanismTable` of the preset's runs under ``root`` (evaluated runs of the
    current configuration for the return shares, trained ones for the gradient shares:
    `distgprl.report.runs.select_runs`), with the ``reach`` rows of
    `distgprl.experiments.mechanisms.reach_rows`."""
    evaluated = select_runs(root, preset)
    trained = select_runs(root, preset, marker="done.json")
    returns, plateau = [], []
    for (task, method), folders in _by_run(evaluated.current, lambda s: s.distance_rewards).items():
        for policy in ("final", "best"):
            name = evaluation_file_names(None, policy)[0]
            rows = {f: read_csv(f / name)[1] for f in folders if (f / name).exists()}
            if rows:
                runs = [(rows[f], _env(f, "sd_d_min")) for f in rows]
                returns += return_cells(task, method, policy, runs)
            scales = [(rows[f], _task_returns(f, task)) for f in rows]
            if (cell := plateau_cell(task, method, policy, scales)) is not None:
                plateau.append(cell)
    gradients = []
    regularised = _by_run(
        trained.current, lambda s: s.trainable and (s.similarity_loss or s.hap_prior)
    )
    for (task, method), folders in regularised.items():
        progress = [read_csv(f / "progress.csv")[1] for f in folders]
        gradients += gradient_cells(task, method, progress)
    if not (reach or returns or gradients):
        raise UserInputError(f"{Path(root) / preset}: no runs to tabulate; run a sweep first")
    note = ". ".join(dict.fromkeys(part for part in (evaluated.note(), trained.note()) if part))
    return MechanismTable(
        preset, tuple(reach), tuple(returns), tuple(gradients), note, tuple(plateau)
    )


DESCRIPTION = (
    "the mechanism table (FINDINGS Protocol v6 rule 7): reach against the TC range, shaping "
    "shares of the return, regulariser shares of the actor gradient (distgprl.report.mechanisms)"
)


def write_mechanisms(
    root: str | Path, preset: str, out_dir: str | Path, reach: Sequence[Mapping[str, Any]]
) -> tuple[list[Path], list[str]]:
    """Write ``<out_dir>/mechanisms_<preset>.csv`` (with its sidecar, `write_table_files`)
    and ``.md``; returns (the paths written, the one-line verdicts per term)."""
    csv, markdown, verdicts = mechanism_texts(mechanism_table(root, preset, reach))
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

COVER_TOLERANCE = 1e-9
"""Reach equal to the TC range up to rounding (m) covers it (the reach rule sets it equal)."""

MARKS = {"yes": " ✓", "no": " ✗"}
TERM_LABELS = {
    "r_sd": "r_sd / r_tc",
    "r_ga": "λ_ga r_ga / r_tc",
    "l_sim": "λ_sim L_sim / Q",
    "l_hap": "λ_hap L_hap / Q (all samples)",
    "l_hap_active": "λ_hap L_hap / Q outside C_safe",
}
ITEMS = tuple(item for item, _ in GRADIENT_ITEMS)
"""The gradient items, in their table's column order."""

REACH_COLUMNS = ("one_step_min_m", "one_step_max_m", "episode_min_m", "episode_max_m", "tc_range_m")
"""The reach rows' distances (m) in the CSV."""

RETURN_CSV_NAMES = {"term": "item", "policy": "where"}
RETURN_CSV_NAMES |= {"within": "episodes_within_d_min", "zero_tc": "episodes_zero_tc"}
"""`ReturnCell` fields under their `CSV_COLUMNS` names (the others keep theirs)."""


def _order(cell: ReturnCell | GradientCell | PlateauCell | tuple[str, str]) -> tuple[int, int, str]:
    """Sort key of a cell or a (task, method): tasks in the paper's order, methods in Table
    I's (unknown ones after)."""
    task, method = cell if isinstance(cell, tuple) else (cell.task, cell.method)
    index = TABLE_ORDER.index(method) if method in TABLE_ORDER else len(TABLE_ORDER)
    return task_order(task), index, method


def _in_order(table: MechanismTable) -> MechanismTable:
    """``table`` with its cells in the tables' order: by `_order`, then the return shares by
    policy (final, best) and term, the gradient shares by point and item, the plateau by
    policy."""
    policy, point, item = ("final", "best").index, POINTS.index, ITEMS.index
    returns = sorted(table.returns, key=lambda c: (*_order(c), policy(c.policy), c.term))
    gradients = sorted(table.gradients, key=lambda c: (*_order(c), point(c.point), item(c.item)))
    plateau = sorted(table.plateau, key=lambda c: (_order(c), c.policy))
    return replace(table, returns=(*returns,), gradients=(*gradients,), plateau=(*plateau,))


def _label(method: str) -> str:
    return METHODS[method].label if method in METHODS else method


def _number(value: float | None) -> str:
    return "" if value is None else f"{value:.6g}"


def _percent(value: float | None) -> str:
    return "–" if value is None else f"{100 * value:.1f} %"


def _steps(steps: Sequence[int]) -> str:
    if not steps:
        return ""
    return str(min(steps)) if min(steps) == max(steps) else f"{min(steps)}–{max(steps)}"


def _mean(values: Sequence[float]) -> float | None:
    return sum(values) / len(values) if values else None


def covers_tc_range(rows: Sequence[Mapping[str, Any]]) -> str:
    """``yes`` where a method and task's smallest one-episode reach is at least the TC range
    on x and on y, ``no`` otherwise, ``n/a`` for reach in ProMP weight units."""
    if any(row["kind"] == "ProMP weight" for row in rows):
        return "n/a"
    planar = [row for row in rows if row["axis"] in ("x", "y")]
    ok = all(row["episode_min_m"] >= row["tc_range_m"] - COVER_TOLERANCE for row in planar)
    return "yes" if ok and planar else "no"


ReachGroup = tuple[str, str, list[Mapping[str, Any]], str]
"""(task, method, its reach rows, `covers_tc_range` of them)."""


def _reach_groups(reach: Iterable[Mapping[str, Any]]) -> list[ReachGroup]:
    """The reach rows per method and task, in `_order`."""
    groups: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for row in reach:
        groups.setdefault((row["task"], row["method"]), []).append(row)
    ordered = sorted(groups.items(), key=lambda item: _order(item[0]))
    return [(task, method, rows, covers_tc_range(rows)) for (task, method), rows in ordered]


def _csv_rows(reach: list[ReachGroup], table: MechanismTable) -> list[dict[str, Any]]:
    """The `CSV_COLUMNS` rows (keys beyond them left out): reach, then the return shares,
    then the gradient shares."""
    rows: list[dict[str, Any]] = [
        {**row, **{key: _number(row[key]) for key in REACH_COLUMNS}, "item": row["axis"]}
        | {"section": "reach", "covers_tc_range": covers}
        for *_, group, covers in reach
        for row in group
    ]
    for cell in table.returns:
        named = {RETURN_CSV_NAMES.get(key, key): value for key, value in asdict(cell).items()}
        shares = {"share_mean": _number(cell.mean), "share_median": _number(cell.median)}
        rows.append(named | shares | {"section": "return_share", "meets_criterion": cell.verdict})
    for gradient in table.gradients:
        named = asdict(gradient) | {"where": gradient.point, "step": _steps(gradient.steps)}
        shares = {"share_mean": _number(gradient.mean)}
        shares["active_fraction"] = _number(_mean(gradient.active_fraction))
        counts = {"seeds": len(gradient.steps), "meets_criterion": gradient.verdict}
        rows.append(named | shares | counts | {"section": "gradient_share"})
    for plateau in table.plateau:
        for item, ratios, bound in _rule_one(plateau):
            keys = {"task": plateau.task, "method": plateau.method, "where": plateau.policy}
            shares = {"share_mean": _number(_mean(ratios)), "share_max": _number(max(ratios))}
            judged = {"meets_criterion": "yes" if max(ratios) <= bound else "no"}
            counts = {"seeds": plateau.seeds, "episodes": len(ratios)}
            named = keys | {"item": item, "section": "reward_scale"}
            rows.append(named | shares | judged | counts)
    return rows


def _rule_one(cell: PlateauCell) -> Iterator[tuple[str, tuple[float, ...], float]]:
    """(item, ratios, bound) of rule 1's measured ratios in ``cell`` that have ratios."""
    for item, ratios, bound in (
        ("ga_of_success", cell.ga_of_success, MAX_GA_SHARE_OF_SUCCESS),
        ("idle_of_demo", cell.idle_of_demo, MAX_IDLE_SHARE_OF_DEMO),
    ):
        if ratios:
            yield item, ratios, bound


def _spans(axes: Sequence[Mapping[str, Any]], span: str) -> str:
    """The ``span`` (``one_step`` or ``episode``) reach's min–max (m) per axis of ``axes``."""
    return " / ".join(f"{row[f'{span}_min_m']:.3f}–{row[f'{span}_max_m']:.3f}" for row in axes)


def _reach_rows(reach: list[ReachGroup], _: MechanismTable) -> Iterator[list[str]]:
    for task, method, group, covers in reach:
        by_axis = sorted(group, key=lambda row: "xyz".index(row["axis"]))
        kind, gate = group[0]["kind"], group[0].get("gate_max")
        yield [
            task.upper(),
            _label(method),
            kind if gate is None else f"{kind}, × gate ≤ {gate:.2f}",
            " / ".join(f"{row['tc_range_m']:.3f}" for row in by_axis),
            *(_spans(by_axis, span) for span in ("one_step", "episode")),
            covers + MARKS.get(covers, ""),
        ]


def _return_text(cell: ReturnCell) -> str:
    if cell.verdict == NOT_RECORDED:
        return NOT_RECORDED
    if cell.mean is None:
        return "– (no episode within d_min)"
    return f"{_percent(cell.mean)} (median {_percent(cell.median)})" + MARKS[cell.verdict]


def _return_rows(_: list[ReachGroup], table: MechanismTable) -> Iterator[list[str]]:
    for (task, method, policy), group in groupby(
        table.returns, key=lambda c: (c.task, c.method, c.policy)
    ):
        terms = {cell.term: cell for cell in group}
        first = next(iter(terms.values()))
        recorded = first.recorded > 0
        yield [
            task.upper(),
            _label(method),
            policy,
            str(first.seeds),
            f"{first.within} of {first.episodes}" if recorded else NOT_RECORDED,
            str(first.zero_tc) if recorded else "",
            _return_text(terms["r_sd"]),
            _return_text(terms["r_ga"]),
        ]


def _gradient_text(cell: GradientCell | None) -> str:
    if cell is None:
        return "—"
    if cell.mean is None:
        return cell.verdict
    return _percent(cell.mean) + MARKS.get(cell.verdict, "")


def _gradient_rows(_: list[ReachGroup], table: MechanismTable) -> Iterator[list[str]]:
    for (task, method, point), group in groupby(
        table.gradients, key=lambda c: (c.task, c.method, c.point)
    ):
        items = {cell.item: cell for cell in group}
        steps = next(iter(items.values())).steps
        active = items.get("l_hap_active")
        fraction = _mean(active.active_fraction) if active is not None else None
        yield [
            task.upper(),
            _label(method),
            f"{point} ({_steps(steps)})",
            str(len(steps)),
            *(_gradient_text(items.get(item)) for item in ITEMS),
            "—" if fraction is None else _percent(fraction),
        ]


def _plateau_rows(_: list[ReachGroup], table: MechanismTable) -> Iterator[list[str]]:
    for cell in table.plateau:
        yield [
            cell.task.upper(),
            _label(cell.method),
            cell.policy,
            str(cell.seeds),
            f"{cell.idle} of {cell.episodes} ({_percent(cell.share)})",
            "–" if cell.mean_ga is None else f"{cell.mean_ga:.3f}",
            _bounded(cell.ga_of_success, MAX_GA_SHARE_OF_SUCCESS),
            _bounded(cell.idle_of_demo, MAX_IDLE_SHARE_OF_DEMO),
        ]


def _bounded(ratios: Sequence[float], bound: float) -> str:
    """``max 2.1 % (mean 0.4 %) ✓``: the largest and the mean of ``ratios``, marked against
    rule 1's ``bound`` (✓ where the largest is within it); – without ratios."""
    if not ratios:
        return "–"
    largest = max(ratios)
    mark = MARKS["yes" if largest <= bound else "no"]
    return f"max {_percent(largest)} (mean {_percent(_mean(ratios))}){mark}"


LISTED_FAILURES = 4
"""A verdict line names at most this many failing cells (else their count and range)."""

OTHER_VERDICTS = {"n/a": "no episode within d_min", "inactive": "inactive (inside C_safe)"}
"""How a verdict line names the cells the criterion does not judge."""


def _verdict(label: str, judged: list[tuple[str, str, float | None]]) -> str:
    """One line: how many cells meet the criterion, which do not, and the term's verdict."""
    no = [(name, value) for name, verdict, value in judged if verdict == "no"]
    other = Counter(verdict for _, verdict, _ in judged)
    decided = other.pop("yes", 0) + other.pop("no", 0)
    if not decided:
        line = f"{label}: undecided (no cell where it acts and is recorded)"
    else:
        outcome = "does not meet the criterion" if no else "meets the criterion"
        line = f"{label}: {outcome} — ≥ {100 * CRITERION:.0f} % in {decided - len(no)} of "
        line += f"{decided} cells"
    if len(no) > LISTED_FAILURES:
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


def _verdict_lines(reach: list[ReachGroup], table: MechanismTable) -> list[str]:
    """One line per mechanism: reach, r_sd, lambda_ga r_ga, lambda_sim L_sim and lambda_hap
    L_hap (outside C_safe), of the ordered (`_in_order`) ``table``."""
    lines = []
    if reach:
        pairs = [(task, method, covers) for task, method, _, covers in reach if covers != "n/a"]
        missing = [f"{task}/{method}" for task, method, covers in pairs if covers == "no"]
        line = (
            f"Reach: the one-episode reach covers the TC range on x and y for "
            f"{sum(covers == 'yes' for *_, covers in pairs)} of {len(pairs)} method–task pairs"
        )
        lines.append(line + (f"; not for {', '.join(missing)}." if missing else "."))
    for term in ("r_sd", "r_ga"):
        if cells := [c for c in table.returns if c.term == term]:
            judged = [(f"{c.task}/{c.method} ({c.policy})", c.verdict, c.mean) for c in cells]
            lines.append(_verdict(f"{TERM_LABELS[term]} (episodes within d_min)", judged))
    for item in ("l_sim", "l_hap_active"):
        if gradients := [c for c in table.gradients if c.item == item]:
            judged = [(f"{c.task}/{c.method} {c.point}", c.verdict, c.mean) for c in gradients]
            lines.append(_verdict(TERM_LABELS[item], judged))
    return lines + _rule_one_lines(table)


RULE_ONE_LABELS = {
    "ga_of_success": "Rule 1 (a), λ_ga Σ r_ga of an episode over a success's r_tc",
    "idle_of_demo": "Rule 1 (b), an idle episode's return over the demonstration's mean r_tc",
}
"""The verdict line's name of each of rule 1's measured ratios."""


def _rule_one_lines(table: MechanismTable) -> list[str]:
    """Per rule-1 ratio: in how many plateau cells the largest measured ratio is within the
    bound, and the largest of all with its cell."""
    lines = []
    for item, label in RULE_ONE_LABELS.items():
        cells = [(c, r, b) for c in table.plateau for i, r, b in _rule_one(c) if i == item]
        if not cells:
            continue
        within = sum(max(ratios) <= bound for _, ratios, bound in cells)
        cell, ratios, bound = max(cells, key=lambda entry: max(entry[1]))
        lines.append(
            f"{label}, measured on the policies' evaluation episodes: within "
            f"{100 * bound:.0f} % in {within} of {len(cells)} cells; largest "
            f"{_percent(max(ratios))} ({cell.task}/{cell.method}, {cell.policy})."
        )
    return lines


INTRO = (
    'Whether the paper\'s mechanisms act (docs/FINDINGS.md "Protocol v6", rule 7). '
    f"Criterion, pre-registered: each shaping term ≥ {100 * CRITERION:.0f} % of |r_tc| over "
    "the evaluation episodes that pass within d_min, each regulariser's actor gradient ≥ "
    f"{100 * CRITERION:.0f} % of the Q term's at the start, middle and end of a paper-size "
    "run (L_hap: over the samples outside C_safe, where it acts). ✓/✗ mark each cell."
)
"""The Markdown's paragraph under its heading."""

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
        ["Task", "Method", "Point (step)", "Seeds", *(TERM_LABELS[item] for item in ITEMS)]
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
"""The Markdown's tables in order: (title, header, its rows of (reach groups, the ordered
table), the definition written under it); the plateau's (a description, no verdict) only
where the table has plateau cells."""


def mechanism_texts(table: MechanismTable) -> tuple[str, str, list[str]]:
    """(CSV text, Markdown text, verdict lines) of the table."""
    table = _in_order(table)
    reach = _reach_groups(table.reach)
    verdicts = _verdict_lines(reach, table)
    markdown = f"## Mechanism table ({table.preset})\n\n{INTRO}\n\n"
    for title, header, rows, definition in SECTIONS[: 4 if table.plateau else 3]:
        table_text = markdown_table(title, header, rows(reach, table))
        markdown += f"{table_text}\n{definition}\n\n"
    lines = ["", "### Verdicts", "", *(f"- {line}" for line in verdicts)]
    if table.note:
        lines += ["", table.note + "."]
    csv = csv_text(_csv_rows(reach, table), CSV_COLUMNS)
    return csv, markdown + "\n".join(lines) + "\n", verdicts
