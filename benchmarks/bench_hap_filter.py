"""Cost of L_hap's moving-obstacle filter (environment v4) on real replay samples.

    python benchmarks/bench_hap_filter.py dbm

Collects 256 observations of Dist-GPRL's environment under random actions (x 0.3), then times
the regulariser's forward and backward (lambda_sim L_sim + lambda_hap L_hap, batch 256, one
thread) with and without the filter (medians of 20, three repeats), and prints the tool box the
filter grows the obstacles by and how many L_hap queries the filter touched.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import torch

from distgprl.experiments.factories import build_regulariser, make_env
from distgprl.identity import resolve_run


def main(task: str) -> None:
    torch.set_num_threads(1)
    run = resolve_run(task, "dist-gprl", 0, "paper")
    env = make_env(run)
    regulariser = build_regulariser(env, run)
    moving = env.moving_obstacle_filter()
    offset, half = env.tool_box()
    print(f"{task}: tool box centre {offset.round(3)} m, half extents {half.round(3)} m")
    rng = np.random.default_rng(0)
    aux = []
    observation, _ = env.reset(seed=1)
    while len(aux) < 256:
        aux.append(observation["aux"])
        action = rng.uniform(-1, 1, env.action_space.shape) * 0.3
        observation, _, terminated, _, _ = env.step(action)
        if terminated:
            observation, _ = env.reset(seed=int(rng.integers(1_000_000)))
    batch = torch.as_tensor(np.array(aux))
    actions = torch.tensor(
        rng.uniform(-1, 1, (256, env.action_space.shape[0])),
        dtype=torch.float32,
        requires_grad=True,
    )
    for label, filter_ in (("without filter", None), ("with filter", moving)):
        regulariser.moving_filter = filter_
        medians = []
        for _ in range(3):
            times = []
            for _ in range(20):
                start = time.perf_counter()
                total, terms = regulariser(batch, actions)
                total.backward()
                times.append(time.perf_counter() - start)
            medians.append(1000 * float(np.median(times)))
        print(f"  {label}: {', '.join(f'{m:.1f}' for m in medians)} ms, L_hap {terms['l_hap']:.4f}")
    print(f"  queries: {regulariser.hap_prior.last_moving_counts}")
    env.close()


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "dbm")
