"""How far trained policies move the via-points, against how far one step's action can.

    python scripts/adaptation_probe.py results/paper/dbm/dist-gprl*/seed2 [--episodes 100]

For each trained run folder (its ``config.json`` and ``model.zip``), re-runs the run's
deterministic policy on the first ``--episodes`` evaluation TCs (100: Table I's) and prints one
markdown row per run:

- *reach* x, y, z (mm): the largest move one step's action can give one via-point along the
  axis (every raw entry saturated with the signs of S_W's row; `correlation_summary`'s
  ``reach``, here from the run's own action layout: the action scale without the transform);
- mean |a| x, y, z: the mean magnitude of the raw action entries of that axis (in [0, 1];
  near 1 the policy presses on the action bound);
- share |a| >= 0.9 x, y, z;
- final move x, y, z (mm): per episode the largest |Gamma - Gamma_0| over the adapted
  via-points, median and 90th percentile over the episodes (a via-point shared by two
  windows can move by two steps' reach);
- success where the episode's x move is above / at most its median: whether the episodes
  that move more succeed more.

Nothing is written: it reads the run folders and the code's environment.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from distgprl.experiments.factories import make_env
from distgprl.experiments.policies import load_trained_policy
from distgprl.experiments.rollout import deterministic_policy
from distgprl.identity import resolve_run
from distgprl.schema import read_json

POSITION_AXES = ("x", "y", "z")


def probe(folder: Path, episodes: int) -> dict[str, np.ndarray | float | str]:
    """The figures of the module docstring for one trained run folder."""
    recorded = read_json(folder / "config.json")["run"]
    preset = folder.parent.parent.parent.name
    run = resolve_run(recorded["task"], recorded["method"]["name"], recorded["seed"], preset)
    env = make_env(run)
    try:
        trained = load_trained_policy(run, folder, env)
        policy = deterministic_policy(trained.model)
        layout = env.unwrapped.layout
        reach = np.abs(layout.operators).sum(axis=3).max(axis=(0, 2)) * layout.scale
        adapted = np.unique(layout.indices)
        actions, moves, successes = [], [], []
        for tc in env.unwrapped.spec_task.evaluation_tcs(episodes):
            observation, _ = env.reset(options={"tc": tc})
            done = False
            while not done:
                action = policy(observation)
                actions.append(np.asarray(action, dtype=float).reshape(-1, 6))
                observation, _, terminated, truncated, info = env.step(action)
                done = terminated or truncated
            delta = info["final_parameters"] - env.unwrapped.gamma_initial
            moves.append(np.abs(delta[adapted]).max(axis=0))
            successes.append(bool(info["success"]))
    finally:
        env.close()
    magnitude = np.abs(np.concatenate(actions))
    moves_array, success = np.array(moves), np.array(successes)
    more = moves_array[:, 0] > np.median(moves_array[:, 0])
    return {
        "run": f"{run.task} {run.method.name} seed {run.seed}",
        "success": float(success.mean()),
        "reach": reach[:3],
        "mean_action": magnitude.mean(axis=0)[:3],
        "share_bound": (magnitude >= 0.9).mean(axis=0)[:3],
        "move_median": np.median(moves_array, axis=0)[:3],
        "move_p90": np.percentile(moves_array, 90, axis=0)[:3],
        "success_more": float(success[more].mean()) if more.any() else float("nan"),
        "success_less": float(success[~more].mean()),
    }


def _cells(values: np.ndarray, scale: float = 1.0, digits: int = 0) -> str:
    return " / ".join(f"{scale * v:.{digits}f}" for v in values)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+", type=Path, help="trained run folders")
    parser.add_argument("--episodes", type=int, default=100, help="evaluation TCs (prefix)")
    arguments = parser.parse_args()
    print(
        "| run | success | reach x / y / z (mm) | mean abs(a) x / y / z | share abs(a) >= 0.9 "
        "| final move median (mm) | final move p90 (mm) | success, x move above / at most "
        "median |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for folder in arguments.folders:
        row = probe(folder, arguments.episodes)
        print(
            f"| {row['run']} | {row['success']:.2f} | {_cells(row['reach'], 1e3)} "
            f"| {_cells(row['mean_action'], digits=2)} | {_cells(row['share_bound'], digits=2)} "
            f"| {_cells(row['move_median'], 1e3)} | {_cells(row['move_p90'], 1e3)} "
            f"| {row['success_more']:.2f} / {row['success_less']:.2f} |"
        )


if __name__ == "__main__":
    main()
