"""Continue a finished run beyond its preset's step count, in a separate results root.

Exploration, not a result of the paper presets: copies a finished run's final checkpoint
(model, replay buffer, RNG state) and learning curve into ``<dest-root>`` and trains on to
``--steps`` with everything else unchanged, then evaluates on the same 100 TCs. The source
run is only read. Answers "would this run do better with more steps?" without training
again from scratch.

Run::

    DISTGPRL_CHECKPOINT_ROOT=/root/.cache/distgprl/checkpoints \
    python scripts/extend_run.py results/paper/dbm/dist-gprl/seed1 \
        results/exploration/longer-training --steps 45000

``DISTGPRL_CHECKPOINT_ROOT`` must match the one the source run was trained with (it says
where the source checkpoint is); the extended run keeps its checkpoints in
``<dest-root>/.../checkpoints`` (git-ignored).
"""

from __future__ import annotations

import argparse
import os
import shutil
from pathlib import Path

from distgprl.experiments.checkpoints import checkpoint_dir, has_checkpoint
from distgprl.experiments.training import train_run
from distgprl.identity import resolve_run
from distgprl.schema import read_json, run_dir, write_json


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "source", type=Path, help="finished run folder <root>/<preset>/<task>/<method>/seed<k>"
    )
    parser.add_argument("dest_root", type=Path, help="results root of the extended run")
    parser.add_argument("--steps", type=int, required=True, help="new total RL steps")
    args = parser.parse_args()

    source = args.source
    if not (source / "done.json").exists():
        raise SystemExit(f"{source}: not a finished run (no done.json)")
    config = read_json(source / "config.json")["run"]
    preset, task, method, seed = (
        config["config"]["preset"],
        config["task"],
        config["method"]["name"],
        int(config["seed"]),
    )
    done_steps = int(read_json(source / "done.json")["steps"])
    if args.steps <= done_steps:
        raise SystemExit(f"--steps {args.steps} must exceed the source's {done_steps}")
    source_checkpoints = checkpoint_dir(source)
    if not has_checkpoint(source):
        raise SystemExit(f"{source_checkpoints}: no final checkpoint to continue from")

    run = resolve_run(task, method, seed, preset, args.steps)
    dest = run_dir(args.dest_root, preset, task, method, seed)
    if dest.exists():
        raise SystemExit(f"{dest}: exists; delete it to extend again")
    dest.mkdir(parents=True)
    os.environ.pop("DISTGPRL_CHECKPOINT_ROOT", None)  # the copy lives under dest
    shutil.copytree(source_checkpoints, checkpoint_dir(dest))
    shutil.copy2(source / "progress.csv", dest / "progress.csv")
    write_json(
        dest / "config.json",
        {"run": run.to_dict(), "config_hash": run.hash, "extended_from": str(source)},
        kind="config",
        config_hash=run.hash,
        seed=seed,
    )
    train_run(task, method, seed, preset, args.steps, resume=True, root=args.dest_root)


if __name__ == "__main__":
    main()
