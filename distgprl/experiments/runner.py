"""Train and evaluate one (task, method, seed) run; results under one versioned folder.

Layout of a run folder ``<root>/<preset>/<task>/<method>/seed<k>/``:

- ``config.json``     resolved configuration, method spec, config hash (written first);
- ``progress.csv``    learning-curve evaluations (success, collision, return) every
                      ``eval_every`` steps on the fixed learning-curve TCs;
- ``checkpoints/``    latest model, replay buffer and RNG state (never committed);
- ``checkpoints/curve_policies/step<k>.pt``  the actor at each learning-curve point that
                      beat every earlier one (`curve_rank`), for ``--policy best`` (never
                      committed);
- ``model.zip``       the final policy, the one Table I evaluates (never committed);
- ``evaluation.csv``  one row per evaluation episode;
- ``summary.json``    success rate, collision rate, MinCl (5th percentile), means;
- ``evaluation_n<N>.csv``, ``summary_n<N>.json``  optional supplementary evaluation on the
                      first N evaluation TCs (``distgprl evaluate --episodes N``);
- ``evaluation_best[_n<N>].csv``, ``summary_best[_n<N>].json``  optional evaluation of the
                      best learning-curve policy, Algorithm 1's "best policy"
                      (``distgprl evaluate --policy best``, `best_curve_row`);
- ``tb/``             TensorBoard event files (losses, alpha, regulariser terms, gradient
                      norms, training episodes, learning curve; `training_logger`; only with
                      the optional ``tensorboard`` package; never committed);
- ``done.json``       marker written last: the run is complete (steps, training wall
                      time, and the steps it was resumed at, each marked exact or not).

Every file is written atomically, so a killed run leaves either the previous file or
the new one, never half of one.

The code lives in one module per concept; this module re-exports their public names so
that ``from distgprl.experiments.runner import ...`` keeps working:

- `distgprl.experiments.factories`   the environment, regulariser and agent of a run; a
                                     saved model checked against an environment;
- `distgprl.experiments.rollout`     episodes, their rows and summary, the deterministic
                                     actor;
- `distgprl.experiments.checkpoints` the checkpoint transaction (save, settle, load);
- `distgprl.experiments.policies`    the kept learning-curve policies, the best one, a
                                     trained run's policy;
- `distgprl.experiments.run_control` the run folder's lock, interrupts, the resume command;
- `distgprl.experiments.training`    `train_run`: start, training loop, ``done.json``;
- `distgprl.experiments.evaluation`  `evaluate_run`.
"""

from __future__ import annotations

from distgprl.experiments.checkpoints import (
    checkpoint_dir,
    has_checkpoint,
    load_checkpoint,
    save_checkpoint,
)
from distgprl.experiments.evaluation import (
    describe,
    evaluate_run,
)
from distgprl.experiments.factories import (
    build_regulariser,
    load_model,
    make_agent,
    make_env,
)
from distgprl.experiments.policies import (
    TrainedPolicy,
    beats_every_earlier,
    best_curve_row,
    curve_policy_dir,
    curve_policy_path,
    curve_rank,
    drop_curve_policies_after,
    load_curve_policy,
    load_trained_policy,
    save_curve_policy,
)
from distgprl.experiments.rollout import (
    deterministic_policy,
    evaluate_policy,
    run_episode,
    summarise,
)
from distgprl.experiments.run_control import (
    TrainingInterrupted,
    describe_interrupt,
    resume_command,
    run_lock,
)
from distgprl.experiments.training import (
    train_run,
)
from distgprl.identity import (
    RunSpec,
    check_seed,
    resolve_run,
)
from distgprl.io import (
    atomic_write_bytes,
    atomic_write_text,
    is_locked,
)
from distgprl.schema import (
    EVALUATION_FIELDS,
    PROGRESS_FIELDS,
    csv_meta_path,
    evaluation_file_names,
    read_csv,
    read_json,
    run_dir,
    safe_success_rate,
    write_csv,
    write_json,
)

__all__ = [
    "EVALUATION_FIELDS",
    "PROGRESS_FIELDS",
    "RunSpec",
    "TrainedPolicy",
    "TrainingInterrupted",
    "atomic_write_bytes",
    "atomic_write_text",
    "beats_every_earlier",
    "best_curve_row",
    "build_regulariser",
    "check_seed",
    "checkpoint_dir",
    "csv_meta_path",
    "curve_policy_dir",
    "curve_policy_path",
    "curve_rank",
    "describe",
    "describe_interrupt",
    "deterministic_policy",
    "drop_curve_policies_after",
    "evaluate_policy",
    "evaluate_run",
    "evaluation_file_names",
    "has_checkpoint",
    "is_locked",
    "load_checkpoint",
    "load_curve_policy",
    "load_model",
    "load_trained_policy",
    "make_agent",
    "make_env",
    "read_csv",
    "read_json",
    "resolve_run",
    "resume_command",
    "run_dir",
    "run_episode",
    "run_lock",
    "safe_success_rate",
    "save_checkpoint",
    "save_curve_policy",
    "summarise",
    "train_run",
    "write_csv",
    "write_json",
]
