"""Reach of each trainable method's raw action, for the mechanism table.

The mechanism table is docs/findings/protocol.md, rule 7.

How far a raw action in [-1, 1] can move what a method adapts, per position axis (x, y, z, m),
computed from the environment the method's runs train in (`distgprl.experiments.factories.
make_env`, so the layout is exactly the one `AdaptationEnv` builds: the reach rule's scales,
S_W per axis, the frozen via-points, ``episode_range``):

- **one step**: via-point i of step k moves at most scale_a * sum_j |S_W,ij| on axis a (the
  row gain, `distgprl.skill.operator.row_gains`; 1 for the methods without S, e.g. the
  global methods, whose per-step scale already carries ``episode_range``'s division by the
  number of steps); the smallest and largest over the adapted, non-frozen via-points and the
  steps;
- **one episode**: the sum of via-point i's one-step reaches over the steps that adapt it —
  one step for a windowed via-point, two for the overlap via-point two windows share, every
  step (3) for a global method;
- **ProMP-RRL as residual RL** (``residual-control``, `distgprl.envs.residual_control_env`): its
  residual (m) moves at most range * dt / ``SLEW_TIME_S`` per RL step of span dt (one step:
  the shortest and longest step) and reaches its range rho per axis over an episode
  (`distgprl.adaptation.residual_control.residual_range`); the commanded pose gets g(t) rho,
  the variance gate g in [0, 1] (its largest value is returned as ``gate_max``);
- the windowed-weights ProMP-RRL (``residual``, an exploration method) adapts ProMP weights,
  not poses: its numbers are in weight units (``kind`` says so).

The table itself (Markdown, CSV, the shares of the return and of the actor gradient from the
result files) is `distgprl.report.mechanisms`, which takes these rows as data.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from distgprl.adaptation.layout import ActionLayout
from distgprl.methods import METHODS, REPORTED_METHODS, MethodSpec

__all__ = [
    "AXES",
    "layout_reach",
    "reach_rows",
    "residual_reach",
    "row_gains_and_moving",
    "run_pairs",
]

AXES = ("x", "y", "z")
"""The position axes the table reports (the TCs vary positions only)."""


def row_gains_and_moving(layout: ActionLayout) -> tuple[np.ndarray, np.ndarray]:
    """(gains, moving): the position rows' gains sum_j |S_W,ij| per step, axis and slot
    (n_steps, 3, A_v), and which slots adapt a via-point (not a frozen one), (n_steps, A_v)."""
    gains: np.ndarray = np.abs(layout.operators[:, :3]).sum(axis=-1)
    moving: np.ndarray = ~np.isin(layout.indices, np.asarray(layout.frozen, dtype=int))
    return gains, moving


def layout_reach(layout: ActionLayout) -> dict[str, np.ndarray]:
    """One-step and one-episode reach of a via-point layout, per position axis, m.

    Returns ``one_step_min``, ``one_step_max``, ``episode_min``, ``episode_max``, each (3,):
    over the via-points the layout adapts (its ``frozen`` ones, which never move, left out)
    and, for one step, over the steps (module docstring).
    """
    gains, moving = row_gains_and_moving(layout)
    step_reach = gains * layout.scale[None, :3, None]  # m per unit raw action
    if not moving.any():
        raise ValueError("the layout adapts no via-point")
    one_step = step_reach.transpose(1, 0, 2)[:, moving]  # (3, adapted (step, point) pairs)
    points = np.unique(layout.indices[moving])
    episode = np.zeros((3, len(points)))
    for k in range(layout.n_steps):
        for slot, index in enumerate(layout.indices[k]):
            if moving[k, slot]:
                episode[:, np.searchsorted(points, index)] += step_reach[k, :, slot]
    return {
        "one_step_min": one_step.min(axis=1),
        "one_step_max": one_step.max(axis=1),
        "episode_min": episode.min(axis=1),
        "episode_max": episode.max(axis=1),
    }


def residual_reach(
    residual_scale: np.ndarray, step_duration: np.ndarray, slew_time: float
) -> dict[str, np.ndarray]:
    """`layout_reach`'s four arrays (3,), m, for a slew-limited residual: its range per
    position axis ``residual_scale[:3]`` (m) is the episode's reach; one RL step of span dt
    (``step_duration`` (n,), s) moves it at most range * dt / ``slew_time`` (s)."""
    scale = np.asarray(residual_scale, dtype=float)[:3]
    duration = np.asarray(step_duration, dtype=float)
    return {
        "one_step_min": scale * float(duration.min()) / slew_time,
        "one_step_max": scale * float(duration.max()) / slew_time,
        "episode_min": scale.copy(),
        "episode_max": scale.copy(),
    }


def env_reach(env: Any, method: MethodSpec) -> tuple[str, dict[str, np.ndarray], float | None]:
    """(kind, `layout_reach`-style arrays, largest gate or None) of a method's environment:
    kind ``via-point`` (window, global), ``residual`` (residual-control) or ``ProMP weight``
    (the windowed-weights residual)."""
    if method.action_mode == "residual-control":
        from distgprl.adaptation.residual_control import SLEW_TIME_S

        reach = residual_reach(env.residual_scale, env.schedule.step_duration, SLEW_TIME_S)
        return "residual", reach, float(np.max(env.gate))
    kind = "ProMP weight" if method.action_mode == "residual" else "via-point"
    return kind, layout_reach(env.layout), None


def run_pairs(root: str | Path, preset: str) -> list[tuple[str, str, int]]:
    """(task, method, seed) of the first seed folder of each trainable method's runs under
    ``<root>/<preset>/<task>/<method>/seed<k>``, sorted by task and method, of the methods
    the reports read (`REPORTED_METHODS`)."""
    base = Path(root) / preset
    pairs = []
    for method_dir in sorted(p for p in base.glob("*/*") if p.is_dir()):
        seeds = sorted(method_dir.glob("seed*"))
        if method_dir.name not in REPORTED_METHODS or not seeds:
            continue
        if not METHODS[method_dir.name].trainable:
            continue
        seed = int(seeds[0].name.removeprefix("seed"))
        pairs.append((method_dir.parent.name, method_dir.name, seed))
    return pairs


def reach_rows(root: str | Path, preset: str) -> list[dict[str, Any]]:
    """The reach rows of the mechanism table for the preset's runs under ``root``: per
    trainable method and task with runs (`run_pairs`) and position axis, ``task``,
    ``method``, ``axis``, ``kind``, ``one_step_min_m``, ``one_step_max_m``,
    ``episode_min_m``, ``episode_max_m``, ``tc_range_m`` (the task's `TaskSpec.tc_range` on
    the axis) and ``gate_max`` (residual-control only, else None). Builds each method's
    environment from the preset (one simulator client at a time, closed after use)."""
    from distgprl.experiments.factories import make_env
    from distgprl.identity import resolve_run

    rows: list[dict[str, Any]] = []
    for task, method, seed in run_pairs(root, preset):
        run = resolve_run(task, method, seed, preset)
        env = make_env(run)
        try:
            kind, reach, gate_max = env_reach(env, run.method)
            tc_range = np.asarray(env.spec_task.tc_range, dtype=float)
        finally:
            env.close()
        for axis, name in enumerate(AXES):
            rows.append(
                {
                    "task": task,
                    "method": method,
                    "axis": name,
                    "kind": kind,
                    **{f"{key}_m": float(value[axis]) for key, value in reach.items()},
                    "tc_range_m": float(tc_range[axis]),
                    "gate_max": gate_max,
                }
            )
    return rows
