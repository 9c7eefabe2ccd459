"""Table I + repair: what the hardware safety layer costs and saves in simulation.

One row per task and method of the current runs (`select_runs`) evaluated with the safety
layer in the loop in both `MODES` (``check``: refuse every unsafe window; ``repair``: re-time
what is too fast, then refuse what is still unsafe; `distgprl.experiments.repair_follow_ups`),
over the seeds that have both, beside their plain evaluation on the same TCs. `FIELDS`:
``<mode>_<outcome>`` the mean over seeds of the per-run rate (success is safe success; a
refused episode is neither a success nor a collision); ``repair_retimed_windows`` the share of
windows re-timed; ``repair_time_added_s`` the mean time added per episode (s); summed over
seeds, the TCs the repair ``gained`` (plain failed, repair succeeded), ``lost`` (plain
succeeded, repair did not) and where it ``averted`` a collision (plain collided, repair did
not). An evaluation of another config hash or on other TCs is left out and listed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, cast

import pandas as pd

from distgprl.data import task_order
from distgprl.methods import METHODS, TABLE_ORDER
from distgprl.report.markdown import csv_text, markdown_table
from distgprl.report.runs import select_runs
from distgprl.schema import (
    EVALUATION_FIELDS,
    evaluation_file_names,
    read_csv,
    read_json,
    repair_evaluation_file_names,
)

MODES = ("check", "repair")
"""The sweep's modes (`distgprl.experiments.repair_follow_ups.SWEEP_REPAIR_MODES`)."""

RATES: tuple[str, ...] = ("plain_success", "plain_collision")
RATES += tuple(
    f"{mode}_{outcome}" for mode in MODES for outcome in ("success", "collision", "refused")
)

FIELDS: tuple[str, ...] = ("task", "method", "seeds", "n_seeds", "episodes", *RATES)
FIELDS += ("repair_retimed_windows", "repair_time_added_s", "gained", "lost", "averted")


def _outcomes(path: Path, mode: str) -> tuple[Any, pd.DataFrame, pd.DataFrame]:
    """(config hash, TCs, ``<mode>_success``/``_collision``/``_refused`` per TC) of an
    evaluation file; a file without a ``refused`` column refused nothing."""
    meta, rows = read_csv(path)
    columns = [*EVALUATION_FIELDS[:5], "success", "collision", "refused"]
    frame = pd.DataFrame(rows).reindex(columns=columns, fill_value=0).astype(float)
    success, collision, refused = (frame[name] == 1 for name in columns[-3:])
    outcomes = {"success": success & ~collision, "collision": collision, "refused": refused}
    tcs = frame[columns[:5]].round(9)  # episode index and offsets (m)
    return meta.get("config_hash"), tcs, pd.DataFrame(outcomes).add_prefix(f"{mode}_")


def _run(folder: Path) -> dict[str, Any] | str:
    """One run's record (its rates, TC counts and repair summary) or why it is left out."""
    current = read_json(folder / "config.json").get("config_hash")
    _, plain_tcs, plain = _outcomes(folder / evaluation_file_names()[0], "plain")
    frames = [plain]
    for mode in MODES:
        config_hash, tcs, outcomes = _outcomes(
            folder / repair_evaluation_file_names(None, "final", mode)[0], mode
        )
        if config_hash != current:
            return f"{mode} evaluation of config hash {config_hash}, not the run's"
        if not tcs.equals(plain_tcs):
            return f"{mode} evaluation on other TCs than the plain one"
        frames.append(outcomes)
    tc = pd.concat(frames, axis=1)
    summary = read_json(folder / repair_evaluation_file_names(None, "final", "repair")[1])
    counts = summary["summary"]
    task, method, seed = folder.parts[-3:]
    return {
        "task": task,
        "method": method,
        "seed": int(seed.removeprefix("seed")),
        "episodes": len(tc),
        **tc[list(RATES)].mean(),
        "gained": (~tc.plain_success & tc.repair_success).sum(),
        "lost": (tc.plain_success & ~tc.repair_success).sum(),
        "averted": (tc.plain_collision & ~tc.repair_collision).sum(),
        "retimed": counts["windows_retimed"],
        "windows": sum(counts[f"windows_{kind}"] for kind in ("none", "retimed", "refused")),
        "repair_time_added_s": counts["mean_time_added_s"],
    }


def repair_table(root: str | Path, preset: str) -> tuple[list[dict[str, Any]], list[str]]:
    """The `FIELDS` rows in table order, and one line per evaluation left out (run, why)."""
    runs, excluded = [], []
    for folder in sorted(select_runs(root, preset).current):
        modes = [repair_evaluation_file_names(None, "final", mode)[1] for mode in MODES]
        if folder.parent.name in METHODS and all((folder / name).exists() for name in modes):
            run = _run(folder)
            if isinstance(run, str):
                excluded.append(f"{'/'.join(folder.parts[-3:])} ({run})")
            else:
                runs.append(run)
    if not runs:
        return [], excluded
    runs.sort(
        key=lambda r: (task_order(r["task"]), TABLE_ORDER.index(r["method"]), r["task"], r["seed"])
    )
    groups = pd.DataFrame(runs).groupby(["task", "method"], sort=False)
    table = groups.agg(
        seeds=("seed", lambda seeds: " ".join(map(str, seeds))),
        n_seeds=("seed", "size"),
        episodes=("episodes", "sum"),
        **{rate: (rate, "mean") for rate in RATES},
        retimed=("retimed", "sum"),
        windows=("windows", "sum"),
        repair_time_added_s=("repair_time_added_s", "mean"),
        gained=("gained", "sum"),
        lost=("lost", "sum"),
        averted=("averted", "sum"),
    )
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
            " / ".join(f"{row[rate]:.2f}" for rate in RATES[:2]),
            " / ".join(f"{row[rate]:.2f}" for rate in RATES[2:5]),
            " / ".join(f"{row[rate]:.2f}" for rate in RATES[5:]),
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
