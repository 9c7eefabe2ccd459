"""Table I + repair: what the hardware safety layer costs and saves in simulation.

One row per task and method of the current runs evaluated with the safety layer in the loop
in both `MODES` (``check``: refuse every unsafe window; ``repair``: re-time what is too fast,
then refuse what is still unsafe; `distgprl.experiments.repair_follow_ups`), over the seeds
that have both, beside their plain evaluation on the same TCs. `FIELDS`: `RATES`;
``repair_retimed_windows`` the share of windows re-timed; ``repair_time_added_s`` the mean
time added per episode (s); summed over seeds, the TCs the repair ``gained`` (plain failed,
repair succeeded), ``lost`` (plain succeeded, repair did not) and ``averted`` (plain collided,
repair did not). An evaluation of another config hash or on other TCs is left out and listed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, cast

import pandas as pd

from distgprl.methods import METHODS
from distgprl.report.markdown import csv_text, markdown_table
from distgprl.report.paired import evaluated_runs, pair_evaluations
from distgprl.report.runs import select_runs
from distgprl.schema import evaluation_file_names, read_csv, read_json
from distgprl.schema import repair_evaluation_file_names as repair_file_names

MODES = ("check", "repair")
"""The sweep's modes (`distgprl.experiments.repair_follow_ups.SWEEP_REPAIR_MODES`)."""

FIELDS = tuple(
    "task method seeds n_seeds episodes plain_success plain_collision check_success "
    "check_collision check_refused repair_success repair_collision repair_refused "
    "repair_retimed_windows repair_time_added_s gained lost averted".split()
)
RATES = FIELDS[5:13]
"""``<mode>_<outcome>``: the mean over seeds of the per-run rate; success is safe success, a
refused episode neither a success nor a collision."""


def _run(folder: Path) -> dict[str, Any] | str:
    """One run's record (rates, TC counts, repair summary), or why it is left out."""
    current = read_json(folder / "config.json").get("config_hash")
    plain = folder / evaluation_file_names()[0]
    pairs = {}
    for mode in MODES:
        path = folder / repair_file_names(None, "final", mode)[0]
        config_hash = read_csv(path)[0].get("config_hash")
        if config_hash != current:
            return f"{mode} evaluation of config hash {config_hash}, not the run's"
        try:
            rows = pair_evaluations(path, plain, ("safe_success", "collision", "refused"))
        except ValueError:
            return f"{mode} evaluation on other TCs than the plain one"
        pairs[mode] = dict(zip(("success", "collision", "refused"), rows, strict=True))
    summary = read_json(folder / repair_file_names(None, "final", "repair")[1])["summary"]
    success, collision = pairs["repair"]["success"], pairs["repair"]["collision"]
    return {
        **{key: success[key] for key in ("task", "method", "seed")},
        "episodes": success["tcs"],
        "plain_success": success["reference_rate"],
        "plain_collision": collision["reference_rate"],
        **{f"{mode}_{k}": row["run_rate"] for mode in MODES for k, row in pairs[mode].items()},
        "gained": success["only_run"],
        "lost": success["only_reference"],
        "averted": collision["only_reference"],
        "retimed": summary["windows_retimed"],
        "windows": sum(summary[f"windows_{kind}"] for kind in ("none", "retimed", "refused")),
        "repair_time_added_s": summary["mean_time_added_s"],
    }


def repair_table(root: str | Path, preset: str) -> tuple[list[dict[str, Any]], list[str]]:
    """The `FIELDS` rows in task and table order, and one line per run left out (why)."""
    summaries = [repair_file_names(None, "final", mode)[1] for mode in MODES]
    runs, excluded = [], []
    for folder in evaluated_runs(select_runs(root, preset).current, *summaries):
        run = _run(folder)
        if isinstance(run, str):
            excluded.append(f"{'/'.join(folder.parts[-3:])} ({run})")
        else:
            runs.append(run)
    if not runs:
        return [], excluded
    groups = pd.DataFrame(runs).groupby(["task", "method"], sort=False)
    table = groups[[*RATES, "repair_time_added_s"]].mean()
    summed = ["episodes", "gained", "lost", "averted", "retimed", "windows"]
    table[summed] = groups[summed].sum()
    table["seeds"] = groups["seed"].agg(lambda seeds: " ".join(map(str, seeds)))
    table["n_seeds"] = groups.size()
    table["repair_retimed_windows"] = table["retimed"] / table["windows"].clip(lower=1)
    return cast(list[dict[str, Any]], table.reset_index().to_dict("records")), excluded


def repair_texts(root: str | Path, preset: str) -> tuple[str, str] | None:
    """(CSV, Markdown) of `repair_table`; None without rows."""
    rows, excluded = repair_table(root, preset)
    if not rows:
        return None
    header = ["Task", "Method", "Seeds", "Plain S / C", "Check S / C / R", "Repair S / C / R"]
    header += ["Retimed", "Added (s)", "Gained / lost / averted"]
    table = [
        [
            row["task"].upper(),
            METHODS[row["method"]].label,
            row["seeds"],
            *(
                " / ".join(f"{row[rate]:.2f}" for rate in rates)
                for rates in (RATES[:2], RATES[2:5], RATES[5:])
            ),
            f"{row['repair_retimed_windows']:.2f}",
            f"{row['repair_time_added_s']:.2f}",
            f"{row['gained']} / {row['lost']} / {row['averted']}",
        ]
        for row in rows
    ]
    title = (
        f"Table I + repair ({preset} preset, simulation): the hardware safety layer in the loop "
        "on the evaluation TCs; S success, C collision, R refused (means over the seeds listed); "
        "Check refuses every unsafe window, Repair re-times what is too fast and refuses what is "
        "still unsafe; Retimed: share of windows re-timed; Added: mean time added per episode; "
        "gained / lost / averted: TCs (summed over seeds) where Repair succeeds and plain did "
        "not / plain succeeded and Repair does not / plain collided and Repair does not"
    )
    markdown = markdown_table(title, header, table)
    if excluded:
        markdown += f"\nNot tabulated ({len(excluded)}): " + "; ".join(excluded) + "\n"
    rounded = [{k: round(v, 4) if isinstance(v, float) else v for k, v in r.items()} for r in rows]
    return csv_text(rounded, FIELDS), markdown
