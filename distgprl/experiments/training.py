"""Train one run, resumably: the lock on its folder, its start (fresh or from the
checkpoint), the training loop (learning-curve points every ``eval_every`` steps,
checkpoints every ``checkpoint_every``), the final model, its evaluations (the final and the
best trained learning-curve policy) and ``done.json``.

A start that fails before training begins leaves nothing behind (`train_run`); an interrupt
raises `TrainingInterrupted`, which says where training stopped and how to resume it.
"""

from __future__ import annotations

import shutil
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from distgprl.errors import UserInputError
from distgprl.experiments.checkpoints import (
    checkpoint_paths,
    checkpoint_step,
    has_checkpoint,
    load_checkpoint,
    save_checkpoint,
    trained_steps,
)
from distgprl.experiments.evaluation import evaluate_run
from distgprl.experiments.factories import make_agent, make_env
from distgprl.experiments.policies import (
    beats_every_earlier,
    curve_policy_path,
    drop_curve_policies_after,
    is_trained_point,
    save_curve_policy,
    select_best,
)
from distgprl.experiments.rollout import deterministic_policy, evaluate_policy, summarise
from distgprl.experiments.run_control import TrainingInterrupted, run_lock
from distgprl.identity import RunSpec, resolve_run
from distgprl.io import remove_partial_writes
from distgprl.schema import (
    PROGRESS_FIELDS,
    csv_meta_path,
    read_csv,
    read_json,
    run_dir,
    write_csv,
    write_json,
)


def _BarCallback(bar):  # noqa: N802  (a class factory: SB3 is imported lazily)
    """An SB3 callback that advances ``bar`` by one per environment step."""
    from stable_baselines3.common.callbacks import BaseCallback

    class BarCallback(BaseCallback):
        def _on_step(self) -> bool:
            bar.update(1)
            return True

    return BarCallback()


def train_run(
    task: str,
    method: str,
    seed: int,
    preset: str = "paper",
    steps: int | None = None,
    resume: bool = False,
    root: str | Path = "results",
    show_progress: bool = True,
    evaluate_after: bool = True,
) -> Path:
    """Train one run (resumable) and, by default, evaluate it: its final policy and its best
    trained learning-curve policy, the one Table I reports (``policy="best"`` of
    `evaluate_run`; skipped, with a note, when the curve has no trained point or that point's
    actor was not kept). Returns the run folder.

    The request is validated (`resolve_run`) before anything touches the disk, and the run
    folder is locked while it trains (see `run_lock`). A start that fails before training
    begins (say, the environment cannot be built) leaves nothing behind: the folders, the
    lock and the ``config.json`` it created are removed, so the next try starts clean.
    """
    run = resolve_run(task, method, seed, preset, steps)
    if not run.method.trainable:
        raise UserInputError(f"method {method!r} does not train; use `distgprl evaluate`")
    folder = run_dir(root, preset, task, method, seed)
    created = [p for p in (folder, *folder.parents) if not p.exists()]
    try:
        with run_lock(folder):
            for leftover in remove_partial_writes(folder):
                print(
                    f"{folder}: removed {leftover.name}, a write an earlier process did not "
                    "finish (the file it was replacing is intact)",
                    file=sys.stderr,
                )
            return _train_locked(run, folder, preset, resume, root, show_progress, evaluate_after)
    except _StartFailed as failed:
        for path in created:  # innermost first; only the still empty ones this start made
            if path == folder:
                (folder / ".lock").unlink(missing_ok=True)
            try:
                path.rmdir()
            except OSError:
                break
        cause = failed.__cause__
        if cause is None:  # _StartFailed is always raised `from` the start's error
            raise
        raise cause from None


class _StartFailed(Exception):
    """A run's start failed before training began; ``__cause__`` is the error."""


@contextmanager
def _undo_on_failure(path: Path) -> Iterator[None]:
    """Remove ``path`` (a file this start writes) if the block fails, then raise
    `_StartFailed` from the error (`train_run` then removes the folders it made)."""
    existed = path.exists()
    try:
        yield
    except Exception as error:
        if not existed:
            path.unlink(missing_ok=True)
        raise _StartFailed from error


def _train_locked(
    run: RunSpec,
    folder: Path,
    preset: str,
    resume: bool,
    root: str | Path,
    show_progress: bool,
    evaluate_after: bool,
) -> Path:
    import torch

    seed = run.seed
    torch.set_num_threads(run.config.run.torch_threads)
    config_path = folder / "config.json"
    paths = checkpoint_paths(folder)
    if (folder / "done.json").exists() and not resume:
        raise UserInputError(f"{folder}: run is already complete (delete it to train again)")
    if config_path.exists():
        recorded = read_json(config_path).get("config_hash")
        if recorded != run.hash:
            raise UserInputError(
                f"{config_path}: existing run has a different configuration "
                f"({recorded} != {run.hash}); delete it or choose another root"
            )
        if not resume:
            raise UserInputError(f"{folder}: run exists; pass --resume to continue it")
    with _undo_on_failure(config_path):
        write_json(
            config_path,
            {"run": run.to_dict(), "config_hash": run.hash},
            kind="config",
            config_hash=run.hash,
            seed=seed,
        )
        started = _start(run, folder, resume, paths)
    return _train_started(run, folder, preset, root, show_progress, evaluate_after, started)


@dataclass(frozen=True)
class _Started:
    """A run ready for its first training step (`_start`)."""

    env: Any
    eval_env: Any
    model: Any
    curve_tcs: list
    progress_rows: list[dict[str, Any]]
    wall_offset: float
    cpu_offset: float
    resumes: list[dict[str, Any]]


def _start(run: RunSpec, folder: Path, resume: bool, paths: dict[str, Path]) -> _Started:
    """Build the environments and the agent (from the checkpoint when resuming): everything
    before the first training step."""
    seed = run.seed
    env = make_env(run)
    eval_env = make_env(run)
    spec = env.spec_task
    curve_tcs = spec.training_curve_tcs(run.config.run.curve_episodes)
    progress_rows: list[dict[str, Any]] = []
    wall_offset = cpu_offset = 0.0
    # Where the run was resumed, and whether exactly (older checkpoints lack the pending TC
    # and NumPy's generator: their resumes restart the TC sequence); recorded in done.json.
    resumes: list[dict[str, Any]] = []
    # A damaged checkpoint falls back to the previous one, or restarts the run: one line
    # says which file was damaged and what was done, and done.json records it.
    loaded = load_checkpoint(folder, env, run) if resume and has_checkpoint(folder) else None
    damaged = [d.describe() for d in loaded.damaged] if loaded is not None else []
    lost = trained_steps(folder / "progress.csv") if resume else 0
    if loaded is not None and damaged:
        print(loaded.describe(folder, lost), file=sys.stderr)
    if loaded is not None and loaded.model is not None:
        model, state = loaded.model, loaded.state
        wall_offset = state.get("wall_time_s", 0.0)
        cpu_offset = state.get("cpu_time_s", 0.0)  # absent in checkpoints before it was kept
        entry = {"step": int(state["num_timesteps"]), "exact": "pending_tc" in state}
        resumes = [
            *state.get("resumes", []),
            {**entry, **({"damaged": damaged} if damaged else {})},
        ]
        if (folder / "progress.csv").exists():
            _, progress_rows = read_csv(folder / "progress.csv")
            # Rows written before a column was added get it empty (the schema's additions).
            progress_rows = [
                {**dict.fromkeys(PROGRESS_FIELDS, ""), **r}
                for r in progress_rows
                if int(r["step"]) <= model.num_timesteps
            ]
        drop_curve_policies_after(folder, model.num_timesteps)
    else:
        if lost and not damaged:
            # Nothing to resume from although the run had trained (checkpoints are not kept
            # with the results, e.g. a new machine): it restarts, visibly and on record.
            print(
                f"warning: {folder}: no checkpoint in {paths['dir']}; the run had reached step "
                f"{lost} and restarts from step 0",
                file=sys.stderr,
            )
        if lost or damaged:
            restart = {"step": 0, "exact": False, "restarted_after_step": lost}
            resumes = [{**restart, **({"damaged": damaged} if damaged else {})}]
        progress = folder / "progress.csv"
        for stale in (progress, csv_meta_path(progress), paths["dir"]):
            if stale.is_dir():
                shutil.rmtree(stale)
            elif stale.exists():
                stale.unlink()
        model = make_agent(env, run)
        env.reset(seed=seed)
    return _Started(
        env, eval_env, model, curve_tcs, progress_rows, wall_offset, cpu_offset, resumes
    )


class _TrainingLoop:
    """The training steps of one started run (`_start`) up to its total steps: the
    learning-curve points, the checkpoints and the progress bar and logs they report to.

    Training time counts from this object's creation on, plus the time the run had already
    trained before a resume (``started.wall_offset``, ``started.cpu_offset``).
    """

    def __init__(self, run: RunSpec, folder: Path, started: _Started, show_progress: bool):
        self.run, self.folder, self.started = run, folder, started
        self.model = started.model
        self.total = run.config.run.total_steps
        self.start_wall = time.perf_counter()
        self.start_cpu = time.process_time()  # process CPU seconds: honest on a shared machine
        from distgprl.agents.sac import EpisodeLogCallback, training_logger

        # TensorBoard event files in tb/ (a resume purges the killed process's records from
        # the checkpoint's step on); the logger and the callback draw no random numbers.
        self.model.set_logger(training_logger(folder / "tb", self.model.num_timesteps))
        self.episode_log = EpisodeLogCallback()
        self.bar = None
        if show_progress:
            from tqdm import tqdm

            self.bar = tqdm(
                total=self.total,
                initial=self.model.num_timesteps,
                desc=f"{run.task}/{run.method.name}/s{run.seed}",
                unit="step",
                disable=None,  # drawn on a terminal only: no bar redraws in a log file
            )

    def wall_time(self) -> float:
        """Seconds of wall time the run has trained (s)."""
        return self.started.wall_offset + time.perf_counter() - self.start_wall

    def cpu_time(self) -> float:
        """Process CPU seconds the run has trained (s)."""
        return self.started.cpu_offset + time.process_time() - self.start_cpu

    def learn(self, steps: int) -> None:
        """Continue training for ``steps`` environment steps (SB3 keeps the episode going)."""
        callbacks = [self.episode_log]
        if self.bar is not None:
            callbacks.append(_BarCallback(self.bar))
        self.model.learn(
            total_timesteps=steps,
            reset_num_timesteps=False,
            progress_bar=False,
            callback=callbacks,
        )

    def record_curve(self) -> None:
        """Evaluate the deterministic policy on the learning-curve TCs and append the point
        to ``progress.csv`` (and the logs); keep the actor if the point is trained (after the
        first SAC update) and ranks at least as high as every earlier trained one
        (`beats_every_earlier`): the untrained actor is never kept."""
        run, model, progress_rows = self.run, self.model, self.started.progress_rows
        rows = evaluate_policy(
            self.started.eval_env, self.started.curve_tcs, deterministic_policy(model)
        )
        summary = summarise(rows)
        terms = model.last_regulariser_terms
        # Per-term gradient norms on the actor's output (issue 30): own index stream, so the
        # training's random streams and a resume's exactness are untouched.
        norms = model.actor_loss_gradient_norms(seed=run.seed * 1_000_003 + model.num_timesteps)
        progress_rows.append(
            {
                "step": model.num_timesteps,
                "episodes": int(model._episode_num),
                "success_rate": summary["success_rate"],
                "collision_rate": summary["collision_rate"],
                "mean_return": summary["mean_return"],
                "min_clearance_p5": summary["min_clearance_p5"],
                "wall_time_s": self.wall_time(),
                "l_sim": terms.get("l_sim", ""),
                "l_hap": terms.get("l_hap", ""),
                "ent_coef": terms.get("ent_coef", model.current_entropy_coefficient()),
                "grad_q": norms.get("grad_q", ""),
                "grad_sim": norms.get("grad_sim", ""),
                "grad_hap": norms.get("grad_hap", ""),
                "grad_hap_active": norms.get("grad_hap_active", ""),
                "hap_active_fraction": norms.get("hap_active_fraction", ""),
            }
        )
        for key, value in progress_rows[-1].items():
            if key not in ("step", "episodes", "wall_time_s") and value != "":
                model.logger.record(f"curve/{key}", float(value))
        model.logger.dump(step=model.num_timesteps)
        learning_starts = run.config.sac.learning_starts
        if beats_every_earlier(progress_rows[:-1], progress_rows[-1], learning_starts):
            save_curve_policy(self.folder, model)  # before the row: a kill never leaves it unkept
        write_csv(
            self.folder / "progress.csv",
            progress_rows,
            PROGRESS_FIELDS,
            config_hash=run.hash,
            seed=run.seed,
            task=run.task,
            method=run.method.name,
        )

    def checkpoint(self) -> None:
        """Save a checkpoint at the end of the current episode."""
        # Checkpoints are taken between episodes (`rng_state`); a collision can end an
        # episode early, so a checkpoint step can fall inside one: train
        # on to the episode's end first (at most an episode's steps - 1: n_windows - 1, or
        # ProMP-RRL's 0.1 s RL steps - 1).
        while not self.started.env.at_episode_start and self.model.num_timesteps < self.total:
            self.learn(1)
        extra = {
            "wall_time_s": self.wall_time(),
            "cpu_time_s": self.cpu_time(),
            "resumes": self.started.resumes,
        }
        save_checkpoint(self.folder, self.model, self.started.env, extra)

    def train(self) -> None:
        """Train to the total steps: a curve point every ``eval_every`` steps (and at step 0
        of a fresh run), a checkpoint every ``checkpoint_every``, both at the end.

        Raises:
            TrainingInterrupted: on KeyboardInterrupt, with the step of the checkpoint on disk
                then (`checkpoint_step`).
        """
        model, total = self.model, self.total
        eval_every = self.run.config.run.eval_every
        checkpoint_every = self.run.config.run.checkpoint_every
        try:
            if model.num_timesteps == 0 and not self.started.progress_rows:
                self.record_curve()
            while model.num_timesteps < total:
                next_stop = min(
                    total,
                    (model.num_timesteps // eval_every + 1) * eval_every,
                    (model.num_timesteps // checkpoint_every + 1) * checkpoint_every,
                )
                self.learn(next_stop - model.num_timesteps)
                if model.num_timesteps % eval_every == 0 or model.num_timesteps >= total:
                    self.record_curve()
                if model.num_timesteps % checkpoint_every == 0 or model.num_timesteps >= total:
                    self.checkpoint()
        except KeyboardInterrupt as interrupt:
            self.close()
            # The checkpoint as it is on disk now (an interrupt can land inside or just after
            # a save; `has_checkpoint` settles it first): the one a resume continues from.
            on_disk = checkpoint_step(self.folder) if has_checkpoint(self.folder) else None
            raise TrainingInterrupted(
                self.folder, model.num_timesteps, total, on_disk
            ) from interrupt
        self.close()

    def close(self) -> None:
        """Close the training logger and the progress bar."""
        self.model.logger.close()
        if self.bar is not None:
            self.bar.close()


def _train_started(
    run: RunSpec,
    folder: Path,
    preset: str,
    root: str | Path,
    show_progress: bool,
    evaluate_after: bool,
    started: _Started,
) -> Path:
    """Train a started run to its total steps, save and evaluate it, write ``done.json``."""
    loop = _TrainingLoop(run, folder, started, show_progress)
    loop.train()
    tmp = folder / ".model.tmp.zip"
    started.model.save(tmp)
    tmp.replace(folder / "model.zip")
    train_wall, train_cpu = loop.wall_time(), loop.cpu_time()
    started.env.close()
    started.eval_env.close()
    if evaluate_after:
        _evaluate_trained(run, folder, preset, root, show_progress, started.progress_rows)
    total = run.config.run.total_steps
    write_json(
        folder / "done.json",
        {
            "steps": total,
            "train_wall_time_s": train_wall,
            # process CPU seconds of training (curve evaluations included; a run resumed
            # from a checkpoint made before this was recorded counts from the resume on)
            "train_cpu_time_s": train_cpu,
            "cpu_s_per_step": train_cpu / total,
            "resumes": started.resumes,
        },
        kind="done",
        config_hash=run.hash,
        seed=run.seed,
    )
    return folder


def _evaluate_trained(
    run: RunSpec,
    folder: Path,
    preset: str,
    root: str | Path,
    show_progress: bool,
    progress_rows: list[dict[str, Any]],
) -> None:
    """Evaluate the trained run's final policy and, if it has a trained curve point whose
    actor was kept, its best learning-curve policy (`evaluate_run`); otherwise the best-policy
    evaluation is skipped with a note."""
    task, method, seed = run.task, run.method.name, run.seed
    evaluate_run(task, method, seed, preset, root=root, show_progress=show_progress)
    learning_starts = run.config.sac.learning_starts
    if not any(is_trained_point(row, learning_starts) for row in progress_rows):
        print(
            f"note: {folder}: no learning-curve point after the first SAC update (step > "
            f"learning_starts = {learning_starts}); the best-policy evaluation is skipped",
            file=sys.stderr,
        )
        return
    best_step = select_best(progress_rows, learning_starts, folder).step
    if curve_policy_path(folder, best_step).exists():
        evaluate_run(
            task, method, seed, preset, root=root, show_progress=show_progress, policy="best"
        )
    else:  # trained (in part) before curve policies were kept
        print(
            f"note: {folder}: its best learning-curve point has no kept policy; "
            "the best-policy evaluation is skipped",
            file=sys.stderr,
        )
