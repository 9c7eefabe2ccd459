"""DBM diagnostics: where collisions happen, and how much any via-point policy could avoid.

    python scripts/dbm_probe.py gap results/paper/dbm/demo/seed0/evaluation.csv [...]
    python scripts/dbm_probe.py failures results/paper/dbm/dist-gprl/seed*/evaluation.csv
    python scripts/dbm_probe.py oracle 0.03 0.06 0.1
    python scripts/dbm_probe.py adaptation results/paper/dbm/dist-gprl/seed{0,1,2}
    python scripts/dbm_probe.py shrink results/paper/dbm/dist-gprl/seed{0,1,2}

``gap`` bins an evaluation file's episodes by the free space between the two bars (the
target's rear face to the other bar's front face, m; constant during an episode since
both ride the same belt) and prints success and collision per bin.

``failures`` lists every evaluation TC that at least one of the files fails, with its
bar gap and, per file, F (failed), C (collided) or FC (both): TCs failed by every policy
point at the task (near-infeasible without touching), TCs failed by one at that policy.

``oracle`` runs a scripted, TC-aware adaptation through the same env (windows, S_W,
clipping to [-1, 1]) with ``position_action_scale`` set to each value: window
via-points 4-5 follow the target's offset like the conditioned ones, and the
pre-insertion via-points 4-7 move towards the handle so that the hook's 6 cm behind
the TCP stays in front of the other bar's handle. It is a crude hand-made policy, not
an optimum: it shows how much of the collision rate via-point corrections of a given
size can remove at all.

``adaptation`` re-runs a trained run's deterministic policy (its ``model.zip``) on the 100
evaluation TCs and prints, for the TCs where the bars are more than 20 cm apart (no
obstacle near the hook), the mean final adaptation of each adapted via-point, Gamma -
Gamma_0 (m, per axis, along the belt = y), separately for the TCs it succeeds and fails:
what a policy that misses the handle does differently with the hook.

``shrink`` re-runs a trained run's deterministic policy (its ``model.zip``) closed loop with
every action multiplied by a factor (1, 0.75, 0.5, 0.25; 0 is the unadapted reference) on the
first 1 000 evaluation TCs where the bars are < 10 cm or >= 25 cm apart, and prints success,
collision and kinematic retention per factor and gap class: whether the precision misses
where nothing is near come from the size of the adaptation, and what shrinking it costs
where the bars are close.
"""

from __future__ import annotations

import sys

import numpy as np

from distgprl.schema import read_csv
from distgprl.sim.tasks.dbm import SCENE


def bar_gap(object_offset_y: np.ndarray, obstacle_offset_y: np.ndarray) -> np.ndarray:
    """Free space (m) between the target's rear face and the other bar's front face."""
    length = 2.0 * SCENE.bar_half_extents[1]
    target = SCENE.target_start_y + np.asarray(object_offset_y)
    other = SCENE.other_start_y + np.asarray(obstacle_offset_y)
    return target - other - length


BINS = (0.0, 0.05, 0.10, 0.15, 0.20, 0.25, 1.0)


def gap_table(path: str) -> None:
    _, rows = read_csv(path)
    gap = bar_gap(
        np.array([float(r["object_offset_y"]) for r in rows]),
        np.array([float(r["obstacle_offset_y"]) for r in rows]),
    )
    success = np.array([float(r["success"]) for r in rows])
    collision = np.array([float(r["collision"]) for r in rows])
    print(f"{path}: success {success.mean():.2f}, collision {collision.mean():.2f}")
    print("| bar gap (m) | episodes | success | collision |\n|---|---|---|---|")
    for lo, hi in zip(BINS[:-1], BINS[1:], strict=True):
        m = (gap >= lo) & (gap < hi)
        if m.any():
            print(
                f"| {lo:.2f}-{hi:.2f} | {m.sum()} | {success[m].mean():.2f} | "
                f"{collision[m].mean():.2f} |"
            )


def failures(paths: list[str]) -> None:
    table = [read_csv(path)[1] for path in paths]
    first = table[0]
    for path, rows in zip(paths, table, strict=True):
        tcs = [(r["object_offset_y"], r["obstacle_offset_y"]) for r in rows]
        if tcs != [(r["object_offset_y"], r["obstacle_offset_y"]) for r in first]:
            raise SystemExit(f"{path}: not the TCs of {paths[0]}; compare one TC set")
    print("| TC | target dy (m) | other dy (m) | gap (m) | " + " | ".join(paths) + " |")
    print("|---" * (4 + len(paths)) + "|")
    failed_by_all = 0
    for index, row in enumerate(first):
        marks = []
        for rows in table:
            other = rows[index]
            mark = ("F" if other["success"] == "0" else "") + (
                "C" if other["collision"] == "1" else ""
            )
            marks.append(mark or ".")
        if any("F" in m for m in marks):
            failed_by_all += all("F" in m for m in marks)
            dy, oy = float(row["object_offset_y"]), float(row["obstacle_offset_y"])
            print(
                f"| {index} | {dy:+.3f} | {oy:+.3f} | {float(bar_gap(dy, oy)):.3f} | "
                + " | ".join(marks)
                + " |"
            )
    print(f"failed by every file: {failed_by_all}")


def oracle(scale: float, episodes: int = 100) -> None:
    from distgprl.config_types import EnvConfig
    from distgprl.envs.via_point_env import AdaptationEnv

    env = AdaptationEnv("dbm", "dist-gprl", EnvConfig(position_action_scale=scale))
    results = []
    for tc in env.spec_task.evaluation_tcs(episodes):
        env.reset(options={"tc": tc})
        dy = tc.object_offset[1]
        gap = float(bar_gap(dy, tc.obstacle_offset[1]))
        wanted = np.zeros((env.config.n_via_points, 6))
        wanted[[4, 5], 1] += dy
        behind = np.clip(gap - 0.06, 0.02, 0.095)  # TCP distance behind the target's rear face
        wanted[[4, 5, 6, 7], 1] += 0.095 - behind
        remaining = wanted.copy()
        for step in range(env.layout.n_steps):
            indices = env.layout.indices[step]
            operator = env.layout.operators[step]
            raw = np.linalg.solve(operator, remaining[indices]) / env.layout.scale
            raw = np.clip(raw, -1.0, 1.0)
            remaining[indices] -= operator @ (raw * env.layout.scale)
            *_, info = env.step(raw.ravel())
        results.append((info["success"], info["collision"], gap))
    env.close()
    r = np.array(results, dtype=float)
    near = r[:, 2] < 0.2
    print(
        f"position_action_scale {scale}: success {r[:, 0].mean():.2f}, collision "
        f"{r[:, 1].mean():.2f} (bars < 0.2 m apart: collision {r[near, 1].mean():.2f}, "
        f"n = {int(near.sum())})",
        flush=True,
    )


def trained_policy(run_folder: str):
    """(env, deterministic policy) of a trained DBM run folder (its ``model.zip``)."""
    from pathlib import Path

    from distgprl.agents.sac import RegularisedSAC
    from distgprl.experiments.factories import make_env
    from distgprl.experiments.rollout import deterministic_policy
    from distgprl.identity import resolve_run

    folder = Path(run_folder)
    config = read_csv(folder / "evaluation.csv")[0]
    run = resolve_run("dbm", config["method"], int(config["seed"]), config["preset"])
    return make_env(run), deterministic_policy(RegularisedSAC.load_saved(folder / "model.zip"))


def adaptation(run_folder: str, wide_gap: float = 0.2) -> None:
    env, policy = trained_policy(run_folder)
    adapted = np.unique(env.layout.indices)
    displacement = {True: [], False: []}
    for tc in env.spec_task.evaluation_tcs(100):
        observation, _ = env.reset(options={"tc": tc})
        done = False
        while not done:
            observation, _, done, _, info = env.step(policy(observation))
        if bar_gap(tc.object_offset[1], tc.obstacle_offset[1]) > wide_gap:
            delta = info["final_parameters"] - env.gamma_initial
            displacement[bool(info["success"])].append(delta[adapted, :3])
    env.close()
    print(f"{run_folder}: TCs with the bars > {wide_gap} m apart, mean Gamma - Gamma_0 (cm)")
    print(
        "| via-point | "
        + " | ".join(
            f"{'success' if ok else 'failure'} (n={len(displacement[ok])}) x, y, z"
            for ok in (True, False)
        )
        + " |"
    )
    print("|---|---|---|")
    for row, index in enumerate(adapted):
        cells = []
        for ok in (True, False):
            if displacement[ok]:
                mean = 100.0 * np.mean(displacement[ok], axis=0)[row]
                cells.append(", ".join(f"{v:+.1f}" for v in mean))
            else:
                cells.append("–")
        print(f"| {index} | " + " | ".join(cells) + " |")


def shrink(run_folder: str, factors=(1.0, 0.75, 0.5, 0.25), episodes: int = 1000) -> None:
    env, policy = trained_policy(run_folder)
    tcs = env.spec_task.evaluation_tcs(episodes)
    gaps = np.array([float(bar_gap(tc.object_offset[1], tc.obstacle_offset[1])) for tc in tcs])
    classes = {"bars < 10 cm apart": gaps < 0.10, "bars >= 25 cm apart": gaps >= 0.25}
    print(f"{run_folder}: policy actions x factor, first {episodes} evaluation TCs")
    print("| factor | TCs | success | collision | safe success | kinematic retention |")
    print("|---|---|---|---|---|---|")
    for factor in factors:
        outcome = {}
        for index in np.flatnonzero((gaps < 0.10) | (gaps >= 0.25)):
            observation, _ = env.reset(options={"tc": tcs[index]})
            done = False
            while not done:
                observation, _, done, _, info = env.step(factor * policy(observation))
            outcome[index] = (info["success"], info["collision"], info["kinematic_retention"])
        for label, mask in classes.items():
            r = np.array([outcome[i] for i in np.flatnonzero(mask)], dtype=float)
            safe = np.mean(r[:, 0] * (1.0 - r[:, 1]))
            print(
                f"| {factor:g} | {label} (n = {len(r)}) | {r[:, 0].mean():.3f} | "
                f"{r[:, 1].mean():.3f} | {safe:.3f} | {r[:, 2].mean():.2f} |",
                flush=True,
            )
    env.close()


if __name__ == "__main__":
    command, *arguments = sys.argv[1:] or ["help"]
    if command == "gap":
        for argument in arguments:
            gap_table(argument)
    elif command == "failures":
        failures(arguments)
    elif command == "adaptation":
        for argument in arguments:
            adaptation(argument)
    elif command == "shrink":
        for argument in arguments:
            shrink(argument)
    elif command == "oracle":
        for argument in arguments or ["0.03"]:
            oracle(float(argument))
    else:
        print(__doc__)
        sys.exit(2)
