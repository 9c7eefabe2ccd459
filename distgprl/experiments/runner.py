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
"""

from __future__ import annotations

import fcntl
import io
import json
import os
import pickle
import random
import shutil
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from distgprl.errors import RunBusyError, UserInputError
from distgprl.identity import RunSpec, check_seed, resolve_run  # noqa: F401 - re-exported
from distgprl.io import atomic_write_bytes, atomic_write_text, is_locked  # noqa: F401
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


# -- environments and agents ---------------------------------------------------------------
def make_env(run: RunSpec):
    """The adaptation environment for a run (ProMP-RRL uses its residual environment)."""
    if run.method.action_mode == "residual":
        from distgprl.envs.residual import ResidualEnv

        return ResidualEnv(run.task, run.config.env, method=run.method)
    from distgprl.envs.adaptation import AdaptationEnv

    return AdaptationEnv(run.task, run.method, run.config.env)


def build_regulariser(env, run: RunSpec):
    """lambda_sim L_sim + lambda_hap L_hap for methods that use them, else None."""
    method, sac = run.method, run.config.sac
    if not (method.similarity_loss or method.hap_prior):
        return None
    from distgprl.agents.regularisers import ActorRegulariser, RegulariserWeights

    hap_prior = None
    if method.hap_prior:
        from distgprl.envs.tasks import load_task_hap_prior

        hap_prior = load_task_hap_prior(run.task, k=sac.hap_k, temperature=sac.hap_temperature)
    weights = RegulariserWeights(
        lambda_sim=sac.lambda_sim if method.similarity_loss else 0.0,
        lambda_hap=sac.lambda_hap if method.hap_prior else 0.0,
        lambda_velocity=sac.lambda_velocity,
        lambda_acceleration=sac.lambda_acceleration,
    )
    return ActorRegulariser(
        env.skill,
        env.layout,
        weights,
        hap_prior=hap_prior,
        n_similarity_samples=sac.n_similarity_samples,
        n_hap_queries=sac.hap_n_query,
        moving_filter=env.moving_obstacle_filter() if method.hap_prior else None,
    )


def make_agent(env, run: RunSpec):
    """A `RegularisedSAC` configured from the run's shared SAC configuration."""
    from distgprl.agents.sac import RegularisedSAC, StateOnlyExtractor, exponential_anneal

    sac = run.config.sac
    anneal = run.method.entropy == "anneal"
    return RegularisedSAC(
        "MultiInputPolicy",
        env,
        learning_rate=sac.learning_rate,
        # SB3 preallocates the whole buffer (and pickles all of it in checkpoints); a run
        # never stores more than total_steps transitions, so the smaller size is equivalent.
        buffer_size=min(sac.buffer_size, run.config.run.total_steps),
        batch_size=sac.batch_size,
        gamma=sac.gamma,
        tau=sac.tau,
        learning_starts=sac.learning_starts,
        train_freq=sac.train_freq,
        gradient_steps=sac.gradient_steps,
        ent_coef=sac.anneal_start if anneal else f"auto_{sac.ent_coef_init}",
        policy_kwargs={
            "features_extractor_class": StateOnlyExtractor,
            "net_arch": list(sac.net_arch),
            # Fused (single-kernel) Adam: the same update, 2x faster on one CPU thread.
            "optimizer_kwargs": {"fused": True},
        },
        seed=run.seed,
        device="cpu",
        verbose=0,
        regulariser=build_regulariser(env, run),
        entropy_schedule=exponential_anneal(sac.anneal_start, sac.anneal_end) if anneal else None,
        total_training_steps=run.config.run.total_steps,
    )


# -- episodes ----------------------------------------------------------------------------------
def run_episode(env, tc, policy=None) -> dict[str, Any]:
    """One episode on a given TC; ``policy(obs) -> action`` or None (zero action)."""
    obs, _ = env.reset(options={"tc": tc})
    total, policy_time = 0.0, 0.0
    while True:
        start = time.perf_counter()
        action = (
            np.zeros(env.action_space.shape, dtype=np.float32) if policy is None else policy(obs)
        )
        policy_time += time.perf_counter() - start
        obs, reward, terminated, truncated, info = env.step(action)
        total += reward
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
        "kinematic_retention": float(info["kinematic_retention"]),
        "adaptation_ms_w1": adaptation[0],
        "adaptation_ms_w2": adaptation[1],
        "adaptation_ms_w3": adaptation[2],
        "policy_ms": 1000 * policy_time,
        "peak_joint_speed": float(info["peak_joint_speed"]),
    }


def summarise(rows: list[dict[str, Any]]) -> dict[str, float]:
    """Success rate, collision rate, MinCl = 5th percentile of episode min clearance
    (clamped at 0: a distance), safe success (success without collision; equal to success
    from environment v5 on), for v5 rows the completion rate (v4's success) and the 5th
    percentile of the signed minimum clearance (negative: penetration), means of the
    per-episode columns and, for
    rows that record it, the 95th percentile of the episodes' peak joint speed (rad/s) and
    the share of episodes above the hardware safety layer's joint speed limit."""
    if not rows:
        raise ValueError("no episodes to summarise")

    def column(name):
        return np.array([float(r[name]) for r in rows])

    adaptation = np.nansum(
        np.stack([column(f"adaptation_ms_w{k}") for k in (1, 2, 3)], axis=1), axis=1
    )
    distance = np.maximum(column("min_clearance"), 0.0)  # v4 rows hold the signed value
    summary = {
        "episodes": len(rows),
        "success_rate": float(column("success").mean()),
        "collision_rate": float(column("collision").mean()),
        "safe_success_rate": safe_success_rate(rows),
        # MinCl as the paper defines it: a distance, >= 0 (v5); the signed minimum
        # (negative = penetration depth) separately.
        "min_clearance_p5": float(np.percentile(distance, 5)),
        "mean_min_clearance": float(distance.mean()),
        "mean_return": float(column("return").mean()),
        "mean_kinematic_retention": float(column("kinematic_retention").mean()),
        "median_adaptation_ms_per_episode": float(np.median(adaptation + column("policy_ms"))),
        "median_policy_ms_per_episode": float(np.median(column("policy_ms"))),
    }
    if all(r.get("completed", "") != "" for r in rows):  # v5 rows
        # v4's success: the task completed, whether or not a collision happened first.
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

        iterator = tqdm(tcs, desc="evaluate", unit="ep", leave=False)
    rows = []
    for index, tc in enumerate(iterator):
        rows.append({"episode": index, **run_episode(env, tc, policy)})
    return rows


def deterministic_policy(model):
    """The actor's deterministic action, computed with NumPy (`NumpyActor`, same weights;
    ~30x faster than ``model.predict`` for one observation)."""
    from distgprl.agents.sac import NumpyActor

    actor = NumpyActor(model.actor)

    def policy(obs):
        return actor(obs["state"])

    return policy


# -- checkpoints --------------------------------------------------------------------------------
def checkpoint_dir(folder: Path) -> Path:
    """Checkpoints of a run: ``<folder>/checkpoints``, or, when ``DISTGPRL_CHECKPOINT_ROOT``
    is set, the run folder's absolute path mirrored under that root (e.g. a disk that
    outlives the work tree): ``$DISTGPRL_CHECKPOINT_ROOT/<absolute run folder>/checkpoints``.
    Runs of the same preset, task, method and seed under different results roots therefore
    never share (or overwrite) a checkpoint."""
    root = os.environ.get("DISTGPRL_CHECKPOINT_ROOT")
    if not root:
        return folder / "checkpoints"
    return Path(root) / folder.resolve().relative_to(folder.resolve().anchor) / "checkpoints"


def _checkpoint_paths(folder: Path) -> dict[str, Path]:
    ckpt = checkpoint_dir(folder)
    return {
        "dir": ckpt,
        "model": ckpt / "model.zip",
        "buffer": ckpt / "replay_buffer.pkl",
        "state": ckpt / "state.pkl",
        "commit": ckpt / "commit.json",
    }


#: The checkpoint's pieces and the temporary names they are written under first.
_CHECKPOINT_PIECES = (
    ("model", ".model.tmp.zip"),
    ("buffer", ".buffer.tmp.pkl"),
    ("state", ".state.tmp.pkl"),
)


def _install_checkpoint(paths: dict[str, Path]) -> None:
    """Move every written piece into place, then drop the commit marker (idempotent)."""
    for piece, temporary in _CHECKPOINT_PIECES:
        staged = paths["dir"] / temporary
        if staged.exists():
            staged.replace(paths[piece])
    paths["commit"].unlink(missing_ok=True)


def _settle_checkpoint(paths: dict[str, Path]) -> None:
    """Leave one consistent checkpoint after a kill at any point of `save_checkpoint`.

    With the commit marker, every new piece was completely written before the kill: finish
    moving them into place (roll forward). Without it the new pieces may be incomplete:
    drop them and keep the previous checkpoint, which was never touched (roll back)."""
    if paths["commit"].exists():
        _install_checkpoint(paths)
        return
    for _, temporary in _CHECKPOINT_PIECES:
        (paths["dir"] / temporary).unlink(missing_ok=True)


def _trained_steps(progress: Path) -> int:
    """The last step a run's ``progress.csv`` recorded (0 if absent or empty)."""
    if not progress.exists():
        return 0
    try:
        _, rows = read_csv(progress)
    except (OSError, ValueError):
        return 0
    return max((int(row["step"]) for row in rows), default=0)


def has_checkpoint(folder: Path) -> bool:
    """Whether the run has a checkpoint to resume from (settling an interrupted save)."""
    paths = _checkpoint_paths(folder)
    if paths["dir"].exists():
        _settle_checkpoint(paths)
    return paths["state"].exists()


def _rng_state(model, env) -> dict[str, Any]:
    """Everything random a resumed run needs to continue exactly where the run stopped.

    Checkpoints are taken between episodes: SB3 has already reset the environment for the
    next episode, so its TC (``pending_tc``) is stored and that episode is reset again on
    resume instead of drawing a new one. NumPy's global generator is SB3's replay-buffer
    sampler; the torch generator drives the policy's sampled actions.
    """
    import torch

    return {
        "num_timesteps": int(model.num_timesteps),
        "episode_count": int(getattr(model, "_episode_num", 0)),
        "torch": torch.get_rng_state(),
        "numpy_global": np.random.get_state(),  # noqa: NPY002  (SB3 samples with it)
        "python_random": random.getstate(),
        "env_rng": env._rng.bit_generator.state,
        "action_space": model.action_space.np_random.bit_generator.state,
        "pending_tc": env.tc,
    }


def _fsync_file(path: Path) -> None:
    """Flush a written file's data to the disk."""
    descriptor = os.open(path, os.O_RDONLY)
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)


def save_checkpoint(folder: Path, model, env, extra: dict[str, Any]) -> None:
    """Model, replay buffer and RNG state, replaced together: a kill at any point leaves
    either the previous checkpoint or this one, never a mix of the two (`has_checkpoint`).

    The three pieces are written under temporary names, then a commit marker is written
    atomically, then the pieces are moved into place and the marker removed."""
    paths = _checkpoint_paths(folder)
    paths["dir"].mkdir(parents=True, exist_ok=True)
    staged = {piece: paths["dir"] / temporary for piece, temporary in _CHECKPOINT_PIECES}
    model.save(staged["model"])
    model.save_replay_buffer(staged["buffer"])
    for piece in ("model", "buffer"):  # on disk before the marker commits them (power loss)
        _fsync_file(staged[piece])
    state = {**_rng_state(model, env), **extra}
    atomic_write_bytes(staged["state"], pickle.dumps(state))
    atomic_write_text(paths["commit"], json.dumps({"num_timesteps": int(model.num_timesteps)}))
    _install_checkpoint(paths)


def load_checkpoint(folder: Path, env, run: RunSpec):
    """(model, state) from the run's checkpoint; a clear error if it is unusable."""
    import torch

    from distgprl.agents.sac import RegularisedSAC

    paths = _checkpoint_paths(folder)
    try:
        state = pickle.loads(paths["state"].read_bytes())
        model = RegularisedSAC.load_saved(paths["model"], env=env)
        model.load_replay_buffer(paths["buffer"])
    except Exception as exc:  # any unreadable piece makes the checkpoint unusable
        raise UserInputError(
            f"{paths['dir']}: corrupt or incompatible checkpoint ({type(exc).__name__}: {exc}); "
            "delete the run folder to start over"
        ) from None
    if model.num_timesteps != state["num_timesteps"]:
        raise UserInputError(
            f"{paths['dir']}: model (step {model.num_timesteps}) and state "
            f"(step {state['num_timesteps']}) are from different checkpoints; "
            "delete the run folder to start over"
        )
    if model.replay_buffer.size() < min(state["num_timesteps"], model.buffer_size):
        raise UserInputError(f"{paths['buffer']}: replay buffer is shorter than the checkpoint")
    fresh = make_agent(env, run)  # rebuild the non-pickled parts from the task and config
    model.regulariser = fresh.regulariser
    model.entropy_schedule = fresh.entropy_schedule
    model.total_training_steps = fresh.total_training_steps
    if "pending_tc" in state:  # checkpoints before this field resume with a fresh episode
        # The episode SB3 had reset when the checkpoint was taken, reset again on its TC
        # (no random draw), so SB3 does not reset the environment with a new one. Loading
        # re-seeded the vectorised env, whose next reset would also re-seed the env's TC
        # generator: reset first, restore every generator after.
        model.env.set_options({"tc": state["pending_tc"]})
        model._last_obs = model.env.reset()
        np.random.set_state(state["numpy_global"])  # noqa: NPY002
        random.setstate(state["python_random"])
    torch.set_rng_state(state["torch"])
    env._rng.bit_generator.state = state["env_rng"]
    model.action_space.np_random.bit_generator.state = state["action_space"]
    return model, state


# -- learning-curve policies (Algorithm 1's "best policy") --------------------------------
def curve_policy_dir(folder: Path) -> Path:
    """Where a run keeps the actors of its best-so-far learning-curve points (checkpoints)."""
    return checkpoint_dir(folder) / "curve_policies"


def curve_policy_path(folder: Path, step: int) -> Path:
    """The kept actor of the learning-curve point at ``step``."""
    return curve_policy_dir(folder) / f"step{int(step)}.pt"


def curve_rank(row: dict[str, Any]) -> tuple[float, float, float]:
    """How learning-curve points are ordered when Algorithm 1's "best policy" is selected:
    higher success rate on the learning-curve TCs, then lower collision rate, then higher
    mean return. The curve TCs are drawn from their own stream, never the evaluation TCs, so
    selecting on them and evaluating on the evaluation TCs is an honest model selection."""
    return (
        float(row["success_rate"]),
        -float(row["collision_rate"]),
        float(row["mean_return"]),
    )


def best_curve_row(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The best learning-curve point (`curve_rank`; the earliest of equal ones)."""
    if not rows:
        raise UserInputError("no learning-curve points to select the best policy from")
    return max(rows, key=curve_rank)  # max keeps the first of equal ones


def save_curve_policy(folder: Path, model) -> None:
    """Keep the model's actor (weights only) as the learning-curve policy of its step."""
    import torch

    buffer = io.BytesIO()
    torch.save(model.actor.state_dict(), buffer)
    path = curve_policy_path(folder, model.num_timesteps)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, buffer.getvalue())


def drop_curve_policies_after(folder: Path, step: int) -> None:
    """Delete kept curve policies of points after ``step`` (a resume discards those points)."""
    directory = curve_policy_dir(folder)
    if not directory.is_dir():
        return
    for path in directory.glob("step*.pt"):
        if int(path.stem.removeprefix("step")) > step:
            path.unlink()


def load_curve_policy(folder: Path, model, step: int) -> None:
    """Replace the model's actor by the kept learning-curve actor of ``step``."""
    import torch

    path = curve_policy_path(folder, step)
    if not path.exists():
        raise UserInputError(
            f"{path}: the best learning-curve point (step {step}) has no kept policy: it was "
            "trained before training kept curve policies, or on another machine (they stay "
            "in the checkpoint folder of the machine that trained the run)"
        )
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
        model.actor.load_state_dict(state)
    except Exception as exc:
        raise UserInputError(
            f"{path}: cannot load the curve policy ({type(exc).__name__}: {exc})"
        ) from None


# -- train ----------------------------------------------------------------------------------
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
    """Train one run (resumable) and, by default, evaluate it: its final policy (Table I)
    and its best learning-curve policy (``policy="best"`` of `evaluate_run`; skipped, with a
    note, when that point's actor was not kept). Returns the run folder.

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
            return _train_locked(run, folder, preset, resume, root, show_progress, evaluate_after)
    except _StartFailed as failed:
        for path in created:  # innermost first; only the still empty ones this start made
            if path == folder:
                (folder / ".lock").unlink(missing_ok=True)
            try:
                path.rmdir()
            except OSError:
                break
        raise failed.__cause__ from None


class TrainingInterrupted(KeyboardInterrupt):
    """Training stopped by KeyboardInterrupt (SIGINT; SIGTERM with
    `~distgprl.experiments.sweep.stop_on_interrupt_signals`), with where it stopped.

    Attributes:
        folder: the run folder.
        step: RL steps trained when it stopped.
        total: the run's total RL steps.
        checkpoint_step: the step of the last checkpoint written (a resume continues from
            it), or None if the run had none yet (a resume starts over).
    """

    def __init__(self, folder: Path, step: int, total: int, checkpoint_step: int | None):
        super().__init__(f"{folder}: interrupted at step {step}/{total}")
        self.folder, self.step, self.total = folder, step, total
        self.checkpoint_step = checkpoint_step

    def describe(self, resume_command: str) -> str:
        """Two lines for stderr: where training stopped, what is kept, how to resume."""
        if self.checkpoint_step is None:
            kept = "no checkpoint was written yet, so a resume starts over"
        else:
            kept = f"its checkpoint of step {self.checkpoint_step} is kept"
        return (
            f"train interrupted at step {self.step} of {self.total} ({self.folder}); {kept}.\n"
            f"resume with: {resume_command}"
        )


def describe_interrupt(error: KeyboardInterrupt, command: str) -> str:
    """What `distgprl train` prints when interrupted: `TrainingInterrupted.describe`, or,
    interrupted outside the training steps (setting up, or evaluating after them), one
    line with the resume command."""
    if isinstance(error, TrainingInterrupted):
        return error.describe(command)
    return f"train interrupted outside the training steps; resume with: {command}"


def resume_command(
    task: str,
    method: str,
    seed: int,
    preset: str,
    steps: int | None,
    root: str | Path,
    evaluate_after: bool = True,
) -> str:
    """The exact ``distgprl train ... --resume`` command that continues a run."""
    import shlex

    words = ["distgprl", "train", "--method", method, "--task", task, "--seed", str(seed)]
    words += ["--preset", preset]
    if steps is not None:
        words += ["--steps", str(steps)]
    words += ["--root", str(root), "--resume"]
    if not evaluate_after:
        words.append("--no-evaluate")
    return shlex.join(words)


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


@contextmanager
def run_lock(folder: Path) -> Iterator[None]:
    """Hold an exclusive lock on a run folder (``.lock``) while one process trains it.

    A second process (say, a restarted sweep while a worker of the old one still runs)
    gets a clear error instead of writing the same checkpoints and CSVs concurrently.
    Closing the file (or the holder's exit, however it dies) releases the lock.
    """
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / ".lock", "w") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise RunBusyError(
                f"{folder}: another process is training this run (lock {folder / '.lock'})"
            ) from None
        yield


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
    paths = _checkpoint_paths(folder)
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
    if resume and has_checkpoint(folder):
        model, state = load_checkpoint(folder, env, run)
        wall_offset = state.get("wall_time_s", 0.0)
        cpu_offset = state.get("cpu_time_s", 0.0)  # absent in checkpoints before it was kept
        resumes = [
            *state.get("resumes", []),
            {"step": int(state["num_timesteps"]), "exact": "pending_tc" in state},
        ]
        if (folder / "progress.csv").exists():
            _, progress_rows = read_csv(folder / "progress.csv")
            progress_rows = [r for r in progress_rows if int(r["step"]) <= model.num_timesteps]
        drop_curve_policies_after(folder, model.num_timesteps)
    else:
        lost = _trained_steps(folder / "progress.csv") if resume else 0
        if lost:
            # Nothing to resume from although the run had trained (checkpoints are not kept
            # with the results, e.g. a new machine): it restarts, visibly and on record.
            print(
                f"warning: {folder}: no checkpoint in {paths['dir']}; the run had reached step "
                f"{lost} and restarts from step 0",
                file=sys.stderr,
            )
            resumes = [{"step": 0, "exact": False, "restarted_after_step": lost}]
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
    task, method, seed = run.task, run.method.name, run.seed
    env, eval_env, model = started.env, started.eval_env, started.model
    curve_tcs, progress_rows = started.curve_tcs, started.progress_rows
    wall_offset, resumes = started.wall_offset, started.resumes
    total = run.config.run.total_steps
    eval_every = run.config.run.eval_every
    ckpt_every = run.config.run.checkpoint_every
    start_wall = time.perf_counter()
    start_cpu = time.process_time()  # process CPU seconds: honest on a shared machine
    from distgprl.agents.sac import EpisodeLogCallback, training_logger

    # TensorBoard event files in tb/ (a resume purges the killed process's records from the
    # checkpoint's step on); the logger and the callback draw no random numbers.
    model.set_logger(training_logger(folder / "tb", model.num_timesteps))
    episode_log = EpisodeLogCallback()
    bar = None
    if show_progress:
        from tqdm import tqdm

        bar = tqdm(
            total=total, initial=model.num_timesteps, desc=f"{task}/{method}/s{seed}", unit="step"
        )

    def record_curve():
        rows = evaluate_policy(eval_env, curve_tcs, deterministic_policy(model))
        summary = summarise(rows)
        terms = model.last_regulariser_terms
        # Per-term gradient norms on the actor's output (issue 30): own index stream, so the
        # training's random streams and a resume's exactness are untouched.
        norms = model.actor_loss_gradient_norms(seed=run.seed * 1_000_003 + model.num_timesteps)
        best_before = max((curve_rank(row) for row in progress_rows), default=None)
        progress_rows.append(
            {
                "step": model.num_timesteps,
                "episodes": int(model._episode_num),
                "success_rate": summary["success_rate"],
                "collision_rate": summary["collision_rate"],
                "mean_return": summary["mean_return"],
                "min_clearance_p5": summary["min_clearance_p5"],
                "wall_time_s": wall_offset + time.perf_counter() - start_wall,
                "l_sim": terms.get("l_sim", ""),
                "l_hap": terms.get("l_hap", ""),
                "ent_coef": terms.get("ent_coef", model.current_entropy_coefficient()),
                "grad_q": norms.get("grad_q", ""),
                "grad_sim": norms.get("grad_sim", ""),
                "grad_hap": norms.get("grad_hap", ""),
            }
        )
        for key, value in progress_rows[-1].items():
            if key not in ("step", "episodes", "wall_time_s") and value != "":
                model.logger.record(f"curve/{key}", float(value))
        model.logger.dump(step=model.num_timesteps)
        if best_before is None or curve_rank(progress_rows[-1]) > best_before:
            save_curve_policy(folder, model)  # before the row: a kill never leaves it unkept
        write_csv(
            folder / "progress.csv",
            progress_rows,
            PROGRESS_FIELDS,
            config_hash=run.hash,
            seed=seed,
            task=task,
            method=method,
        )

    def learn(steps: int) -> None:
        """Continue training for ``steps`` environment steps (SB3 keeps the episode going)."""
        model.learn(
            total_timesteps=steps,
            reset_num_timesteps=False,
            progress_bar=False,
            callback=[episode_log] if bar is None else [episode_log, _BarCallback(bar)],
        )

    # The step of the checkpoint on disk (None: none yet), for the message of an interrupt.
    checkpoint_step = model.num_timesteps if has_checkpoint(folder) else None
    try:
        if model.num_timesteps == 0 and not progress_rows:
            record_curve()
        while model.num_timesteps < total:
            next_stop = min(
                total,
                (model.num_timesteps // eval_every + 1) * eval_every,
                (model.num_timesteps // ckpt_every + 1) * ckpt_every,
            )
            learn(next_stop - model.num_timesteps)
            if model.num_timesteps % eval_every == 0 or model.num_timesteps >= total:
                record_curve()
            if model.num_timesteps % ckpt_every == 0 or model.num_timesteps >= total:
                # Checkpoints are taken between episodes (`_rng_state`); since environment v5 a
                # collision ends an episode early, so a checkpoint step can fall inside one:
                # train on to the episode's end first (at most n_windows - 1 steps).
                while not env.at_episode_start and model.num_timesteps < total:
                    learn(1)
                extra = {
                    "wall_time_s": wall_offset + time.perf_counter() - start_wall,
                    "cpu_time_s": started.cpu_offset + time.process_time() - start_cpu,
                    "resumes": resumes,
                }
                save_checkpoint(folder, model, env, extra)
                checkpoint_step = model.num_timesteps
    except KeyboardInterrupt as interrupt:
        model.logger.close()
        if bar is not None:
            bar.close()
        raise TrainingInterrupted(
            folder, model.num_timesteps, total, checkpoint_step
        ) from interrupt
    model.logger.close()
    if bar is not None:
        bar.close()
    tmp = folder / ".model.tmp.zip"
    model.save(tmp)
    tmp.replace(folder / "model.zip")
    train_wall = wall_offset + time.perf_counter() - start_wall
    train_cpu = started.cpu_offset + time.process_time() - start_cpu
    env.close()
    eval_env.close()
    if evaluate_after:
        evaluate_run(task, method, seed, preset, root=root, show_progress=show_progress)
        best_step = int(best_curve_row(progress_rows)["step"])
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
    write_json(
        folder / "done.json",
        {
            "steps": total,
            "train_wall_time_s": train_wall,
            # process CPU seconds of training (curve evaluations included; a run resumed
            # from a checkpoint made before this was recorded counts from the resume on)
            "train_cpu_time_s": train_cpu,
            "cpu_s_per_step": train_cpu / total,
            "resumes": resumes,
        },
        kind="done",
        config_hash=run.hash,
        seed=seed,
    )
    return folder


# -- evaluate -------------------------------------------------------------------------------
@dataclass(frozen=True)
class TrainedPolicy:
    """A trained run's policy, loaded by `load_trained_policy`.

    Attributes:
        run: the run as it was trained (with its ``--steps``, if it was trained with them).
        model: the `RegularisedSAC` holding the policy (for ``policy="best"``, with the
            actor of the selected learning-curve point).
        selected: for ``policy="best"``: ``policy``, ``policy_step`` and the selected
            point's curve figures (what the summary records); else empty.
    """

    run: RunSpec
    model: Any
    selected: dict[str, Any]


def load_trained_policy(run: RunSpec, folder: Path, env, policy: str = "final") -> TrainedPolicy:
    """Load the final (``policy="final"``, ``model.zip``) or best learning-curve
    (``policy="best"``) policy of the trained run in ``folder``.

    The run is taken with the configuration it was trained with (its ``total_steps``
    included), which must still be what the code resolves; a model of an older
    configuration, or one whose spaces do not match ``env``'s, is a `UserInputError`.
    """
    task, method, seed, preset = run.task, run.method.name, run.seed, run.config.preset
    model_path = folder / "model.zip"
    if not model_path.exists():
        raise UserInputError(
            f"{model_path}: no trained model; run `distgprl train --method {method} "
            f"--task {task} --seed {seed} --preset {preset}` first"
        )
    trained = read_json(folder / "config.json") if (folder / "config.json").exists() else {}
    steps = trained.get("run", {}).get("config", {}).get("run", {}).get("total_steps")
    if steps is not None and steps != run.config.run.total_steps:  # trained with --steps
        run = resolve_run(task, method, seed, preset, steps)
    recorded = trained.get("config_hash")
    if recorded != run.hash:
        raise UserInputError(
            f"{model_path}: trained with configuration {recorded}, the code now resolves "
            f"{run.hash} for this run; re-train it (evaluating would mislabel the model)"
        )
    from distgprl.agents.sac import RegularisedSAC

    try:
        model = RegularisedSAC.load_saved(model_path)
    except Exception as exc:
        raise UserInputError(
            f"{model_path}: cannot load model ({type(exc).__name__}: {exc})"
        ) from None
    if model.observation_space != env.observation_space or (model.action_space != env.action_space):
        raise UserInputError(
            f"{model_path}: model spaces do not match the {task}/{method} environment"
        )
    selected: dict[str, Any] = {}
    if policy == "best":
        _, curve = read_csv(folder / "progress.csv")
        best = best_curve_row(curve)
        load_curve_policy(folder, model, int(best["step"]))
        selected = {
            "policy": "best",
            "policy_step": int(best["step"]),
            "curve_success_rate": float(best["success_rate"]),
            "curve_collision_rate": float(best["collision_rate"]),
            "curve_mean_return": float(best["mean_return"]),
        }
    return TrainedPolicy(run, model, selected)


def evaluate_run(
    task: str,
    method: str,
    seed: int = 0,
    preset: str = "paper",
    episodes: int | None = None,
    root: str | Path = "results",
    show_progress: bool = True,
    policy: str = "final",
) -> dict[str, Any]:
    """Evaluate a trained run (or the `demo` reference) on the evaluation TCs.

    Writes ``evaluation.csv`` and ``summary.json`` into the run folder; with ``episodes``
    other than the preset's, a supplementary evaluation under the names of
    `evaluation_file_names` instead (the first ``episodes`` TCs of the same stream, so the
    preset's TCs are a prefix); returns the summary. A trained run is evaluated under the
    configuration it was trained with (its ``total_steps`` included), which must still be
    what the code resolves: a model of an older configuration is refused.

    ``policy="best"`` evaluates, instead of the final policy, the best learning-curve policy
    (Algorithm 1's "best policy": `best_curve_row` of ``progress.csv``, its actor kept by
    training) and writes the ``_best`` files of `evaluation_file_names`; the summary records
    the selected step and its curve figures. Only trained runs have one.
    """
    run = resolve_run(task, method, seed, preset)
    episodes = episodes or run.config.run.eval_episodes
    supplementary = episodes != run.config.run.eval_episodes
    csv_name, summary_name = evaluation_file_names(episodes if supplementary else None, policy)
    folder = run_dir(root, preset, task, method, seed)
    if policy == "best" and not run.method.trainable:
        raise UserInputError(f"{method} is not trained: it has no learning curve to select from")
    env = make_env(run)
    actor = None
    selected: dict[str, Any] = {}
    if run.method.trainable:
        trained = load_trained_policy(run, folder, env, policy)
        run, selected = trained.run, trained.selected
        actor = deterministic_policy(trained.model)
    elif not supplementary or not (folder / "config.json").exists():
        # the reference's config is written with its preset evaluation; a supplementary
        # evaluation leaves an existing one untouched (its own files carry their meta)
        write_json(
            folder / "config.json",
            {"run": run.to_dict(), "config_hash": run.hash},
            kind="config",
            config_hash=run.hash,
            seed=seed,
        )
    tcs = env.spec_task.evaluation_tcs(episodes)
    start = time.perf_counter()
    rows = evaluate_policy(env, tcs, actor, progress=show_progress)
    wall = time.perf_counter() - start
    env.close()
    summary = {**summarise(rows), "evaluation_wall_time_s": wall, **selected}
    meta = {"config_hash": run.hash, "seed": seed, "task": task, "method": method, "preset": preset}
    write_csv(folder / csv_name, rows, EVALUATION_FIELDS, **meta)
    write_json(folder / summary_name, {"summary": summary}, kind="summary", **meta)
    return summary


def describe(summary: dict[str, Any]) -> str:
    """One line for the terminal."""
    return json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in summary.items()})
