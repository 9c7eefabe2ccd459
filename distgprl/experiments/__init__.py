"""Experiments: runs, sweeps, their follow-ups and the §V benchmarks.

One (task, method, seed) run is trained and evaluated into one versioned folder
(`distgprl.experiments.training.train_run`, `distgprl.experiments.evaluation.evaluate_run`).

Layout of a run folder ``<root>/<preset>/<task>/<method>/seed<k>/``:

- ``config.json``     resolved configuration, method spec, config hash (written first);
- ``progress.csv``    learning-curve evaluations (success, collision, return) every
                      ``eval_every`` steps on the fixed learning-curve TCs;
- ``checkpoints/``    latest model, replay buffer and RNG state (never committed);
- ``checkpoints/curve_policies/step<k>.pt``  the actor at each trained learning-curve point
                      that ranks at least as high as every earlier trained one
                      (`beats_every_earlier`), for ``--policy best`` (never committed);
- ``model.zip``       the final policy (never committed; Table I reports the best
                      learning-curve policy, ``summary_best.json``);
- ``evaluation.csv``  one row per evaluation episode;
- ``summary.json``    success rate, collision rate, MinCl (5th percentile), means;
- ``evaluation_n<N>.csv``, ``summary_n<N>.json``  optional supplementary evaluation on the
                      first N evaluation TCs (``distgprl evaluate --episodes N``);
- ``evaluation_best[_n<N>].csv``, ``summary_best[_n<N>].json``  evaluation of the best
                      trained learning-curve policy, Algorithm 1's "best policy", the one
                      Table I reports (written after training where its actor was kept;
                      ``distgprl evaluate --policy best``, `best_curve_row`);
- ``policy_best.pt``, ``policy_best.json``  that policy's actor, shipped with the run's small
                      files, and its record (step, SHA-256, ``beats_untrained``;
                      `distgprl.experiments.policies.SHIPPED_POLICY`);
- ``tb/``             TensorBoard event files (losses, alpha, regulariser terms, gradient
                      norms, training episodes, learning curve; `training_logger`; only with
                      the optional ``tensorboard`` package; never committed);
- ``done.json``       marker written last: the run is complete (steps, training wall
                      time, and the steps it was resumed at, each marked exact or not).

Every file is written atomically, so a killed run leaves either the previous file or
the new one, never half of one.

The run's code, one module per concept:

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
