"""Evaluation in simulation with the hardware safety layer between the plan and execution.

`evaluate_with_repair` runs a trained policy with a window plan (or the untrained ``demo``
reference; not the residual-control methods, `distgprl.methods.NO_SAFETY_LAYER`) on the fixed
evaluation TCs exactly as `~distgprl.experiments.evaluation.evaluate_run` does, except that
every window's plan passes the safety layer of the hardware trials
(:mod:`distgprl.safety_layer.plan_check`, :mod:`distgprl.safety_layer.repair`) before it is
executed, as in :func:`~distgprl.hardware.trials.run_trials` under its ``safety-layer``
protocol (`distgprl.trial_protocol`): the episode loop's decisions
(`distgprl.envs.episode`) in the simulator world (`distgprl.envs.world.SimWorld`) behind
the safety layer's `~distgprl.safety_layer.gates.RepairGate`:

1. the policy adapts the window (`AdaptationEnv.apply_action`) and the env gives the
   segment's poses (`AdaptationEnv.segment_poses`, continuity blend included);
2. :func:`~distgprl.safety_layer.repair.repair_plan` pre-flight checks them
   (:func:`~distgprl.safety_layer.plan_check.check_plan`: workspace, IK, joint limits, joint speed
   and acceleration, TCP speed, predicted clearance) and, if unsafe, retimes them
   (TOPP-RA), pushes the window's via-points along the distance field's gradient (only with
   ``push``), or refuses them. The clearance oracle is the simulation's own: the task's
   obstacle shapes predicted along their known paths (`TaskSim.obstacle_shapes` at each
   control instant's time), so the layer sees the obstacles exactly (no perception error);
3. a refused window ends the episode there, before it moves: a *protective refusal*,
   neither a success nor a collision, recorded as ``refused`` with the window and the
   reason; an accepted plan is executed in the PyBullet task simulation (`TaskSim.execute`,
   stopping at a collision as the environment does).

**How a retimed segment is executed.** As the twin backend does
(:class:`~distgprl.hardware.backends.TwinBackend`): the retimed plan is a longer list of
TCP poses, one per control period (25 Hz), and the simulation tracks them one per period,
so a segment retimed by ``+d`` s takes ``d`` s longer and the world runs on for that time:
the obstacles move along their paths (DCP's cube oscillates on, DBM's other bar rides the
belt on) and the object is conveyed on until the robot touches it. Later windows start
that much later (their clearance is predicted at the real times; the policy's observation
is built by the env as in training, from its plan times). While the object is conveyed
(not yet touched), the retimed poses follow it (:mod:`distgprl.safety_layer.repair`, "belt
frame": each pose shifted by the object's conveying velocity times the delay, and later
windows by the shift accumulated so far), so the engagement with the conveyed object is
kept; on DCP only the target cube drifts, the obstacle cube does not ride with it, and the
clearance check sees it at the new times. Pushed via-points are written back into the env's
via-points (the policy observes them in the next window, as on hardware). A window that
passes the check unchanged is executed exactly as `AdaptationEnv.step` executes it.

**Limits.** `simulation_safety_limits`: DBM uses the hardware cell's
:class:`~distgprl.limits.SafetyLimits` unchanged; DCP has no hardware cell, and its shovel
pushes a cube along the table (its TCP 2 mm above the table top, 2.4 mm of predicted
clearance to the table in the demonstration's third window), so its workspace box reaches
down to the table top (z >= 0) and its clearance limit is 2 mm; every other limit is the
hardware's.

Results: ``evaluation_repair.csv`` (:data:`~distgprl.schema.REPAIR_EVALUATION_FIELDS`) and
``summary_repair.json`` in the run folder (``_repair_push`` with the push, ``_check`` for
the layer without repair; :func:`~distgprl.schema.repair_evaluation_file_names`), beside the
plain evaluation, which they never replace.
"""

from __future__ import annotations

import time
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

from distgprl.envs.episode import EpisodeTally, execute_segment, plan_segment
from distgprl.envs.world import SimWorld
from distgprl.errors import UserInputError
from distgprl.limits import SafetyLimits
from distgprl.safety_layer.gates import RepairGate
from distgprl.safety_layer.retime import RepairConfig
from distgprl.schema import (
    REPAIR_EVALUATION_FIELDS,
    read_json,
    repair_evaluation_file_names,
    run_dir,
    write_csv,
    write_json,
)

DCP_TABLE_CLEARANCE = 0.002
"""Clearance limit (m) of the DCP layer: the demonstration's shovel passes 2.4 mm over the
table, a 5 mm limit would refuse the task itself."""


def simulation_safety_limits(task: str) -> SafetyLimits:
    """The safety limits of the simulated layer for ``task`` (module docstring, "Limits")."""
    limits = SafetyLimits()
    if task == "dcp":
        lower = limits.workspace_lower
        return replace(
            limits, workspace_lower=(lower[0], lower[1], 0.0), min_clearance=DCP_TABLE_CLEARANCE
        )
    return limits


def repair_mode(config: RepairConfig) -> str:
    """The file tag (:data:`~distgprl.schema.REPAIR_MODES`) of a repair configuration:
    ``push`` with the via-point push, ``repair`` with retiming only, ``check`` with neither."""
    if config.repair:
        return "push"
    return "repair" if config.retime else "check"


def run_repaired_episode(
    env,
    tc,
    policy=None,
    limits: SafetyLimits | None = None,
    config: RepairConfig | None = None,
) -> dict[str, Any]:
    """One episode on ``tc`` with the safety layer between each window plan and execution.

    Args:
        env: an `AdaptationEnv` (or `ResidualEnv`) of the run.
        tc: the task configuration.
        policy: ``observation -> raw action``, or None (zero action: the references).
        limits: the limits (default `simulation_safety_limits` of the env's task).
        config: the repair settings (default :class:`RepairConfig`: retime, no push;
            ``RepairConfig(retime=False)``: refuse every unsafe window at once).

    Returns:
        One row of :data:`~distgprl.schema.REPAIR_EVALUATION_FIELDS`.
    """
    limits = limits or simulation_safety_limits(env.task_name)
    config = config or RepairConfig()
    observation, _ = env.reset(options={"tc": tc})
    sim = env.sim
    stop_on_collision = env.config.collision_ends_episode
    world = SimWorld(sim, stop_on_collision=stop_on_collision)
    gate = _simulated_safety_layer(env, limits, config)
    tally = EpisodeTally()  # what the executed windows add up to
    refused_window: int | str = ""  # the refused window (1-based); "" if none was
    planned = np.inf
    policy_time = 0.0
    start_clearance = float(sim.clearance())
    for step in range(env.layout.n_steps):
        started = time.perf_counter()
        action = (
            np.zeros(env.action_space.shape, dtype=np.float32)
            if policy is None
            else policy(observation)
        )
        policy_time += time.perf_counter() - started
        _, poses = plan_segment(env, step, action)  # Eq. transformed_action, updated_via_points
        segment = execute_segment(env, world, step, poses, gate).report
        if segment is None:  # a protective refusal: nothing of it moves
            refused_window = step + 1
            break
        assert gate.last.check is not None  # accepted plans are checked
        planned = min(planned, gate.last.check.min_clearance)
        tally.add(segment)
        if stop_on_collision and segment.collision:
            break
        env.field.update(sim.moving_obstacle_shapes())  # as the env's step leaves it
        observation = env.observation()
    refused = refused_window != ""
    windows = gate.reviews
    refused_limits = ",".join(gate.last.refused_limits) if refused else ""
    reason = gate.last.reason if refused else ""
    dt = world.control_dt
    repair_time = gate.seconds
    completed = bool(sim.success())
    success = completed and not refused and not (tally.collision and stop_on_collision)
    min_clearance = tally.min_clearance if tally.steps else start_clearance
    added = [w.time_added for w in windows]
    displacement = [w.displacement for w in windows]
    return {
        "object_offset_x": float(tc.object_offset[0]),
        "object_offset_y": float(tc.object_offset[1]),
        "obstacle_offset_x": float(tc.obstacle_offset[0]),
        "obstacle_offset_y": float(tc.obstacle_offset[1]),
        "success": int(success),
        "completed": int(completed),
        "collision": int(tally.collision),
        "refused": int(refused),
        "refused_window": refused_window,
        "refused_limits": refused_limits,
        "refusal_reason": reason,
        "min_clearance": max(float(min_clearance), 0.0),
        "min_signed_clearance": float(min_clearance),
        "planned_min_clearance": float(planned),
        "peak_joint_speed": float(tally.peak_joint_speed),
        "executed_s": tally.steps * dt,
        "repair": ";".join(w.decision for w in windows),
        "repair_added_s": ";".join(f"{a:.3f}" for a in added),
        "repair_displacement_m": ";".join(f"{d:.4f}" for d in displacement),
        "time_added_s": float(sum(added)),
        "max_displacement_m": float(max(displacement, default=0.0)),
        "policy_ms": 1000.0 * policy_time,
        "repair_ms": 1000.0 * repair_time,
    }


def _simulated_safety_layer(env, limits: SafetyLimits, config: RepairConfig) -> RepairGate:
    """The safety layer of ``env``'s simulation: its own distance field (the env's is left
    untouched) of the task's obstacles predicted along their known paths, the belt the
    conveyed object rides while it is not released."""
    from distgprl.safety.edf import DistanceField

    sim = env.sim

    def belt() -> np.ndarray | None:
        return None if sim.object_released else sim.conveying_velocity

    return RepairGate(
        env,
        sim.robot,
        limits,
        float(sim.control_dt),
        sim.joint_positions(),
        DistanceField(sim.obstacle_shapes()),
        sim.obstacle_shapes,
        lambda: float(sim.time),
        belt,
        config,
    )


def summarise_repaired(rows: list[dict[str, Any]]) -> dict[str, float]:
    """Success, collision and refusal rates over all episodes; mean time added (s) over
    all episodes and over those that were retimed; windows per decision; MinCl (5th
    percentile of the min clearance, m) over the episodes that moved the robot."""
    if not rows:
        raise ValueError("no episodes to summarise")

    def column(name: str) -> np.ndarray:
        return np.array([float(r[name]) for r in rows])

    decisions = [d for r in rows for d in str(r["repair"]).split(";") if d]
    added = column("time_added_s")
    moved = [float(r["min_clearance"]) for r in rows if float(r["executed_s"]) > 0]
    summary: dict[str, float] = {
        "episodes": len(rows),
        "success_rate": float(column("success").mean()),
        "collision_rate": float(column("collision").mean()),
        "refused_rate": float(column("refused").mean()),
        "completion_rate": float(column("completed").mean()),
        "mean_time_added_s": float(added.mean()),
        "mean_time_added_when_retimed_s": float(added[added > 0].mean())
        if np.any(added > 0)
        else 0.0,
        "max_displacement_m": float(column("max_displacement_m").max()),
    }
    for decision in ("none", "retimed", "repaired", "refused"):
        summary[f"windows_{decision}"] = decisions.count(decision)
    if moved:
        summary["min_clearance_p5"] = float(np.percentile(moved, 5))
    limits: dict[str, int] = {}
    for row in rows:
        for name in filter(None, str(row["refused_limits"]).split(",")):
            limits[name] = limits.get(name, 0) + 1
    for name, count in sorted(limits.items()):
        summary[f"refused_for_{name}"] = count
    return summary


def evaluate_with_repair(
    task: str,
    method: str,
    seed: int = 0,
    preset: str = "paper",
    episodes: int | None = None,
    root: str | Path = "results",
    policy: str = "final",
    config: RepairConfig | None = None,
    limits: SafetyLimits | None = None,
    show_progress: bool = True,
) -> dict[str, Any]:
    """Evaluate a trained run (or a reference) with the safety layer in the loop.

    Same run, policy and TCs as `~distgprl.experiments.evaluation.evaluate_run` (the first
    ``episodes`` evaluation TCs, default the preset's); every episode is
    `run_repaired_episode`. Writes the CSV and summary of
    :func:`~distgprl.schema.repair_evaluation_file_names` (mode `repair_mode` of
    ``config``) into the run folder and returns the summary; a reference whose folder has
    no ``config.json`` yet gets one, as its plain evaluation would write it.

    Args:
        task, method, seed, preset, episodes, root, policy: as for ``evaluate_run``.
        config: the repair settings (default :class:`RepairConfig`: retime, no push).
        limits: the limits (default `simulation_safety_limits`).
        show_progress: a progress bar on stderr.

    Raises:
        UserInputError: for a residual-control method (`distgprl.methods.NO_SAFETY_LAYER`).
    """
    from distgprl.methods import NO_SAFETY_LAYER, get_method, has_via_point_plan

    if not has_via_point_plan(get_method(method)):
        raise UserInputError(f"{method}: {NO_SAFETY_LAYER}")
    from distgprl.experiments.factories import make_env
    from distgprl.experiments.policies import load_trained_policy
    from distgprl.experiments.rollout import deterministic_policy
    from distgprl.identity import resolve_run

    config = config or RepairConfig()
    run = resolve_run(task, method, seed, preset)
    n_episodes = episodes or run.config.run.eval_episodes
    supplementary = n_episodes != run.config.run.eval_episodes
    mode = repair_mode(config)
    csv_name, summary_name = repair_evaluation_file_names(
        n_episodes if supplementary else None, policy, mode
    )
    if policy == "best" and not run.method.trainable:
        raise UserInputError(f"{method} is not trained: it has no learning curve to select from")
    folder = run_dir(root, preset, task, method, seed)
    limits = limits or simulation_safety_limits(task)
    env = make_env(run)
    try:
        actor = None
        selected: dict[str, Any] = {}
        if run.method.trainable:
            trained = load_trained_policy(run, folder, env, policy)
            run, selected = trained.run, trained.selected
            actor = deterministic_policy(trained.model)
        elif not (folder / "config.json").exists():
            write_json(
                folder / "config.json",
                {"run": run.to_dict(), "config_hash": run.hash},
                kind="config",
                config_hash=run.hash,
                seed=seed,
            )
        elif read_json(folder / "config.json").get("config_hash") != run.hash:
            raise UserInputError(
                f"{folder}: its config.json is of an older configuration; evaluate the "
                f"reference into a fresh --root (or re-run `distgprl evaluate` on it first)"
            )
        tcs = env.spec_task.evaluation_tcs(n_episodes)
        iterator = tcs
        if show_progress:
            from tqdm import tqdm

            iterator = tqdm(tcs, desc="evaluate+repair", unit="ep", leave=False, disable=None)
        start = time.perf_counter()
        rows = [
            {"episode": index, **run_repaired_episode(env, tc, actor, limits, config)}
            for index, tc in enumerate(iterator)
        ]
        wall = time.perf_counter() - start
    finally:
        env.close()
    summary = {**summarise_repaired(rows), "evaluation_wall_time_s": wall, **selected}
    meta = {
        "config_hash": run.hash,
        "seed": seed,
        "task": task,
        "method": method,
        "preset": preset,
        "repair_mode": mode,
        "repair_config": asdict(config),
        "limits": asdict(limits),
    }
    write_csv(folder / csv_name, rows, REPAIR_EVALUATION_FIELDS, **meta)
    write_json(folder / summary_name, {"summary": summary}, kind="summary", **meta)
    return summary
