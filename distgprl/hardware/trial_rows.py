"""The rows of hardware trials: the bookkeeping columns of a finished trial (`finish_row`),
its judgement (`judge_row`: the twin's simulation, the operator's yes/no or the perceived lift)
and the summary of a trial file's rows (as Table II counts
them)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from distgprl.safety_layer.plan_check import tool_check_points
from distgprl.schema import moved_robot
from distgprl.trial_protocol import PAPER, PROTECTIVE_STOP


def finish_row(
    row: dict[str, Any],
    trial_start: float,
    timings: dict[str, Any],
    errors: list[tuple[float, float]],
    planned: float,
    judge_skip: bool = False,
) -> dict[str, Any]:
    """Fill the bookkeeping columns of a trial's ``row`` (`distgprl.schema.TRIAL_FIELDS`)
    and return it; with ``judge_skip`` (stopped or not perceived before any motion) the
    trial counts as a failure.

    Args:
        row: the trial's row, filled in place.
        trial_start: ``time.perf_counter()`` at the trial's start (s).
        timings: ``perception`` (detection ms per image), ``policy``, ``check`` and
            ``execution`` (s, summed over the windows).
        errors: (position error m, rotation error deg) of each perceived pose (twin only).
        planned: the smallest planned clearance over the windows (m; inf if none).
    """
    if judge_skip:  # stopped or not perceived before any motion
        row["success"] = 0
        row["collision"] = int(row["collision"] == 1)
        row["min_clearance"] = np.inf
    row["planned_min_clearance"] = float(planned)
    if errors:
        array = np.array(errors)
        row["perception_error_mm"] = round(1000.0 * float(array[:, 0].max()), 3)
        row["perception_error_deg"] = round(float(array[:, 1].max()), 3)
    if timings["perception"]:
        row["perception_ms"] = round(float(np.mean(timings["perception"])), 2)
    row["policy_ms"] = round(1000.0 * timings["policy"], 3)
    row["check_ms"] = round(1000.0 * timings["check"], 3)
    row["execution_s"] = round(timings["execution"], 3)
    row["trial_s"] = round(time.perf_counter() - trial_start, 3)
    return row


def ask_yes_no(ask: Callable[[str], str], question: str) -> int:
    """Ask the operator ``question`` until the answer is yes or no: 1 for yes, 0 for no."""
    while True:
        answer = ask(f"{question} [y/n] ").strip().lower()
        if answer in ("y", "yes", "1"):
            return 1
        if answer in ("n", "no", "0"):
            return 0


def judge_row(
    row: dict[str, Any],
    robot: Any,
    adapter: Any,
    *,
    twin: bool,
    judge: str,
    ask: Callable[[str], str],
    index: int,
    perceive: Callable[[], bool],
) -> None:
    """Judge a trial that ran (or stopped) into ``row``, in place: ``min_clearance`` (the
    twin's simulated clearance, else the distance field's at the robot's actual joints, m) and
    its source, ``success`` and ``collision`` — from the twin's simulation (``judge="auto"``
    on the twin), the operator's answers (``judge="operator"``, asked through ``ask`` about
    trial ``index``), or on the real robot the perceived lift of the target bar (a fresh
    ``perceive()``) with a protective stop counted as the collision."""
    if twin:
        row["min_clearance"] = float(robot.min_clearance)
        row["clearance_source"] = "sim"
    else:
        row["min_clearance"] = _edf_clearance(adapter, robot)
        row["clearance_source"] = "edf"
    if twin and judge == "auto":
        row["success"] = int(robot.success())
        row["collision"] = int(bool(robot.collision))
    elif judge == "operator":
        row["success"] = ask_yes_no(ask, f"trial {index + 1}: was the target bar lifted off?")
        row["collision"] = ask_yes_no(
            ask, f"trial {index + 1}: did the robot or tool touch a roller, rail or the other bar?"
        )
    else:  # real robot, automatic: perceived lift; collision = a protective stop
        perceive()
        track = adapter.world.tracks["target_bar"].transform
        lifted = track[2, 3] - adapter.world.scene.bar_centre_z
        row["success"] = int(lifted >= adapter.world.scene.lift_height and row["status"] == "ok")
        row["collision"] = int(row["collision"] == 1)


def _edf_clearance(adapter: Any, robot: Any) -> float:
    """Min distance (m) of the tool/flange at the actual joints to the perceived obstacles."""
    points = tool_check_points(adapter.model.robot, robot.joint_positions())
    adapter.env.field.update(adapter.world.obstacle_shapes())
    return float(adapter.env.field.clearance(points).min())


def summarise_trials(rows: list[dict[str, Any]]) -> dict[str, float]:
    """Success rate, collision rate (over judged trials), MinCl (5th percentile of min
    clearance, over the trials that moved the robot, `moved_robot`; as Table II), counts
    (refusals by the safety layer; protective stops at the robot controller's limits)."""
    executed = [r for r in rows if r["success"] != ""]  # judged: ran, stopped or refused
    if not executed:
        return {"trials": len(rows), "judged": 0}
    moved = [r for r in executed if moved_robot(r)]
    summary = {
        "trials": len(rows),
        "judged": len(executed),
        "moved": len(moved),
        "refused": sum(1 for r in rows if r["status"] == "refused"),
        "protective_stops": sum(1 for r in rows if r["status"] == PROTECTIVE_STOP),
        "success_rate": float(np.mean([float(r["success"]) for r in executed])),
        "collision_rate": float(np.mean([float(r["collision"]) for r in executed])),
        "mean_trial_s": float(np.mean([float(r["trial_s"]) for r in rows])),
    }
    if moved:
        clearance = [float(r["min_clearance"]) for r in moved]
        summary["min_clearance_p5"] = float(np.percentile(clearance, 5))
    return summary


def describe_summary(summary: dict[str, float], protocol: str) -> str:
    """One line of a `summarise_trials` summary, as the CLI and the sweep print it: the
    success and collision rates, the protocol's stops (the paper's: protective stops;
    the safety layer's: refusals) of the trials, and MinCl in millimetres."""
    if not summary.get("judged"):
        return f"no trial judged of {int(summary['trials'])}"
    stops = (
        f"protective stops {int(summary.get('protective_stops', 0))}"
        if protocol == PAPER
        else f"refused {int(summary.get('refused', 0))}"
    )
    line = (
        f"success {summary.get('success_rate', 0.0):.2f}, "
        f"collision {summary.get('collision_rate', 0.0):.2f}, "
        f"{stops} of {int(summary['trials'])}"
    )
    if "min_clearance_p5" in summary:
        line += f", MinCl {1000 * summary['min_clearance_p5']:.1f} mm"
    return line


def describe_trial(row: dict[str, Any]) -> str:
    """One trial's row in a line: its status, then (when judged) success, collision and its
    minimum clearance in millimetres."""
    line = str(row["status"])
    if row["success"] != "":
        line += f", success {row['success']}, collision {row['collision']}"
    if row.get("min_clearance") not in ("", None):
        line += f", min clearance {1000 * float(row['min_clearance']):.1f} mm"
    return line
