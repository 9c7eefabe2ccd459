"""Episodes of a run's environment: one episode's row (`run_episode`), the evaluation of a
policy on a list of TCs, the summary of the rows (Table I's numbers of one run) and the
deterministic actor every evaluation runs."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from distgprl.schema import collision_free_min_clearance_p5, safe_success_rate

#: The reward terms (``info`` keys of `AdaptationEnv` / `ResidualRLEnv`) summed into each
#: ``return_*`` column of an episode row: r_tc = r_progress + r_success + r_collision, r_sd,
#: and lambda_ga r_ga (``info["r_ga"]`` already includes lambda_ga). An env without a term
#: (the residual-RL env has only r_tc's) contributes 0 to its column.
RETURN_TERMS: dict[str, tuple[str, ...]] = {
    "return_tc": ("r_progress", "r_success", "r_collision"),
    "return_sd": ("r_sd",),
    "return_ga": ("r_ga",),
}


def run_episode(env, tc, policy=None) -> dict[str, Any]:
    """One episode on a given TC; ``policy(obs) -> action`` or None (zero action).

    The row's ``return`` is the episode's undiscounted return; ``return_tc``, ``return_sd``
    and ``return_ga`` are its parts (`RETURN_TERMS`, summed over the steps' ``info``), in
    the reward's unit (r_tc in tenths of a task: a task's whole progress is worth
    ``progress_weight`` = 10); GPRL's r_signature is in ``return`` only."""
    obs, _ = env.reset(options={"tc": tc})
    total, policy_time = 0.0, 0.0
    parts = dict.fromkeys(RETURN_TERMS, 0.0)
    while True:
        start = time.perf_counter()
        action = (
            np.zeros(env.action_space.shape, dtype=np.float32) if policy is None else policy(obs)
        )
        policy_time += time.perf_counter() - start
        obs, reward, terminated, truncated, info = env.step(action)
        total += reward
        for column, terms in RETURN_TERMS.items():
            parts[column] += sum(float(info.get(term, 0.0)) for term in terms)
        if terminated or truncated:
            break
    adaptation = [1000 * t for t in info.get("adaptation_time_s", [])] + [np.nan] * 3
    return {
        "object_offset_x": float(tc.object_offset[0]),
        "object_offset_y": float(tc.object_offset[1]),
        "obstacle_offset_x": float(tc.obstacle_offset[0]),
        "obstacle_offset_y": float(tc.obstacle_offset[1]),
        "success": int(info["success"]),
        "completed": int(info["completed"]),
        "collision": int(info["collision"]),
        "min_clearance": float(info["min_clearance"]),
        "min_signed_clearance": float(info["min_signed_clearance"]),
        "return": float(total),
        **parts,
        "kinematic_retention": float(info["kinematic_retention"]),
        "adaptation_ms_w1": adaptation[0],
        "adaptation_ms_w2": adaptation[1],
        "adaptation_ms_w3": adaptation[2],
        "policy_ms": 1000 * policy_time,
        "peak_joint_speed": float(info["peak_joint_speed"]),
    }


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Success rate, collision rate, MinCl (``min_clearance_p5_collision_free``: the 5th
    percentile of the episode-wise minimum clearance over the ``collision_free_episodes``
    episodes without a collision, None where every episode collided;
    `collision_free_min_clearance_p5`; docs/findings/protocol.md, rule 5), MinCl over all
    episodes (``min_clearance_p5``: the 5th percentile of episode min clearance, clamped at
    0: a distance), safe success (success without collision; equal to success wherever a
    collision ends the episode), for rows that record ``completed`` the completion rate
    (the task completed, collision or not) and the 5th percentile of the signed minimum
    clearance (negative: penetration), means of the per-episode columns and, for rows that
    record it, the 95th percentile of the episodes' peak joint speed (rad/s) and the share
    of episodes above the hardware safety layer's joint speed limit."""
    if not rows:
        raise ValueError("no episodes to summarise")

    def column(name):
        return np.array([float(r[name]) for r in rows])

    adaptation = np.nansum(
        np.stack([column(f"adaptation_ms_w{k}") for k in (1, 2, 3)], axis=1), axis=1
    )
    distance = np.maximum(column("min_clearance"), 0.0)  # the oldest rows hold the signed value
    collision_free_p5, collision_free = collision_free_min_clearance_p5(rows)
    summary: dict[str, Any] = {
        "episodes": len(rows),
        "success_rate": float(column("success").mean()),
        "collision_rate": float(column("collision").mean()),
        "safe_success_rate": safe_success_rate(rows),
        # MinCl over all episodes (a secondary column): a distance, >= 0; the signed
        # minimum (negative = penetration depth) separately.
        "min_clearance_p5": float(np.percentile(distance, 5)),
        "mean_min_clearance": float(distance.mean()),
        # MinCl (docs/findings/protocol.md, rule 5): over the collision-free episodes.
        "min_clearance_p5_collision_free": collision_free_p5,
        "collision_free_episodes": collision_free,
        "mean_return": float(column("return").mean()),
        "mean_kinematic_retention": float(column("kinematic_retention").mean()),
        "median_adaptation_ms_per_episode": float(np.median(adaptation + column("policy_ms"))),
        "median_policy_ms_per_episode": float(np.median(column("policy_ms"))),
    }
    if all(r.get("completed", "") != "" for r in rows):  # rows that record completion
        # Completion: the task completed, whether or not a collision happened first.
        summary["completion_rate"] = float(column("completed").mean())
        summary["min_signed_clearance_p5"] = float(np.percentile(column("min_signed_clearance"), 5))
    if all(r.get("peak_joint_speed", "") != "" for r in rows):
        from distgprl.limits import SafetyLimits

        peak = column("peak_joint_speed")
        summary["peak_joint_speed_p95"] = float(np.percentile(peak, 95))
        # Episodes the hardware safety layer would refuse for their joint speed alone.
        summary["joint_speed_over_limit_rate"] = float(
            np.mean(peak > SafetyLimits().max_joint_speed)
        )
    return summary


def evaluate_policy(env, tcs, policy=None, progress: bool = False) -> list[dict[str, Any]]:
    """Run one deterministic episode per TC."""
    iterator = tcs
    if progress:
        from tqdm import tqdm

        iterator = tqdm(tcs, desc="evaluate", unit="ep", leave=False, disable=None)
    rows = []
    for index, tc in enumerate(iterator):
        rows.append({"episode": index, **run_episode(env, tc, policy)})
    return rows


def deterministic_policy(model):
    """The actor's deterministic action, computed with NumPy (`NumpyActor`, same weights;
    ~30x faster than ``model.predict`` for one observation)."""
    from distgprl.agents.numpy_actor import NumpyActor

    actor = NumpyActor(model.actor)

    def policy(obs):
        return actor(obs["state"])

    return policy
