"""Where a training run's time goes, and the before/after of the recommended startup fix.

Run: ``python benchmarks/profile_training.py [--steps 300] [--skip-profile]``.

1. cProfile of a short real training run (paper preset, dcp / dist-gprl, learning_starts
   lowered so that every timed step makes one gradient step): the top functions by
   cumulative and by own time.
2. Process startup (``make_env`` + ``make_agent``, as every ``distgprl train`` / ``evaluate``
   process and every benchmark worker does), in fresh processes: as shipped (the GP skill is
   refitted by marginal likelihood in every process: `distgprl.envs.tasks.load_task_skill`
   caches only in memory) and with a monkeypatched disk cache of the fitted skill (the fix
   recommended for ``distgprl/envs/tasks.py``).
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

STARTUP_SNIPPET = r"""
import json, sys, time
start = time.perf_counter()
if sys.argv[1] == "cached":
    import distgprl.envs.tasks as tasks
    from distgprl.skill.gp import GPSkill
    from distgprl.io import file_sha256
    from pathlib import Path
    original, cache = tasks.load_task_skill, Path(sys.argv[2])

    def load_task_skill(task, n_via_points=15):
        key = f"{task}_{n_via_points}_{file_sha256(tasks.demo_path(task))[:16]}.json"
        path = cache / key
        if path.exists():
            return GPSkill.from_dict(json.loads(path.read_text()))
        skill = original(task, n_via_points)
        cache.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(skill.to_dict()))
        return skill

    tasks.load_task_skill = load_task_skill
from distgprl.experiments.factories import make_agent, make_env
from distgprl.identity import resolve_run
imported = time.perf_counter()
run = resolve_run("dcp", "dist-gprl", 0, "ci")
env = make_env(run)
built = time.perf_counter()
make_agent(env, run)
done = time.perf_counter()
print("RESULT " + json.dumps({"import_s": imported - start, "make_env_s": built - imported,
      "make_agent_s": done - built, "total_s": done - start}))
"""


def profile_training(steps: int) -> None:
    import torch

    from distgprl.config import load_config
    from distgprl.experiments.factories import make_agent, make_env
    from distgprl.identity import RunSpec
    from distgprl.methods import get_method

    torch.set_num_threads(1)
    overrides = {"sac": {"learning_starts": 90, "buffer_size": 20_000}}
    run = RunSpec("dcp", get_method("dist-gprl"), 0, load_config("paper", "dcp", overrides))
    env = make_env(run)
    model = make_agent(env, run)
    env.reset(seed=0)
    model.learn(total_timesteps=93, progress_bar=False)
    profiler = cProfile.Profile()
    start = time.perf_counter()
    profiler.enable()
    model.learn(total_timesteps=steps, reset_num_timesteps=False, progress_bar=False)
    profiler.disable()
    wall = time.perf_counter() - start
    print(f"1. {steps} training steps in {wall:.1f} s ({steps / wall:.1f} steps/s, cProfile on)")
    stats = pstats.Stats(profiler)
    stats.sort_stats("cumulative").print_stats(30)
    stats.sort_stats("tottime").print_stats(20)
    env.close()


def startup(mode: str, cache: Path) -> dict[str, float]:
    out = subprocess.run(
        [sys.executable, "-c", STARTUP_SNIPPET, mode, str(cache)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    line = next(x for x in out.splitlines() if x.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--skip-profile", action="store_true")
    args = parser.parse_args()
    if not args.skip_profile:
        profile_training(args.steps)
    print("2. process startup (make_env + make_agent), fresh processes, seconds")
    with tempfile.TemporaryDirectory() as folder:
        cache = Path(folder)
        startup("cached", cache)  # fills the disk cache (one fit)
        rows: dict[str, list[dict[str, float]]] = {"shipped": [], "disk-cached skill": []}
        for _ in range(args.repeats):  # interleaved: both see the same machine load
            rows["shipped"].append(startup("shipped", cache))
            rows["disk-cached skill"].append(startup("cached", cache))
    for name, results in rows.items():
        cells = "  ".join(
            f"{key} {np.median([r[key] for r in results]):6.2f}"
            for key in ("import_s", "make_env_s", "make_agent_s", "total_s")
        )
        print(f"   {name:18s} median of {len(results)}: {cells}")


if __name__ == "__main__":
    main()
