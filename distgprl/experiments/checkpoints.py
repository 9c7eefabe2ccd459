"""A run's checkpoint (model, replay buffer and RNG state), saved as one transaction: a kill
at any point leaves either the previous checkpoint or the new one (`save_checkpoint`,
`settle_checkpoint`), and a resumed run continues exactly where it stopped
(`load_checkpoint`)."""

from __future__ import annotations

import json
import os
import pickle
import random
from pathlib import Path
from typing import Any

import numpy as np

from distgprl.errors import UserInputError
from distgprl.experiments.factories import make_agent
from distgprl.identity import RunSpec
from distgprl.io import atomic_write_bytes, atomic_write_text
from distgprl.schema import read_csv


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


def checkpoint_paths(folder: Path) -> dict[str, Path]:
    """The checkpoint's folder (``dir``), its pieces (``model``, ``buffer``, ``state``) and
    the commit marker (``commit``) of `save_checkpoint`."""
    ckpt = checkpoint_dir(folder)
    return {
        "dir": ckpt,
        "model": ckpt / "model.zip",
        "buffer": ckpt / "replay_buffer.pkl",
        "state": ckpt / "state.pkl",
        "commit": ckpt / "commit.json",
    }


#: The checkpoint's pieces and the temporary names they are written under first.
CHECKPOINT_PIECES = (
    ("model", ".model.tmp.zip"),
    ("buffer", ".buffer.tmp.pkl"),
    ("state", ".state.tmp.pkl"),
)


def install_checkpoint(paths: dict[str, Path]) -> None:
    """Move every written piece into place, then drop the commit marker (idempotent)."""
    for piece, temporary in CHECKPOINT_PIECES:
        staged = paths["dir"] / temporary
        if staged.exists():
            staged.replace(paths[piece])
    paths["commit"].unlink(missing_ok=True)


def settle_checkpoint(paths: dict[str, Path]) -> None:
    """Leave one consistent checkpoint after a kill at any point of `save_checkpoint`.

    With the commit marker, every new piece was completely written before the kill: finish
    moving them into place (roll forward). Without it the new pieces may be incomplete:
    drop them and keep the previous checkpoint, which was never touched (roll back)."""
    if paths["commit"].exists():
        install_checkpoint(paths)
        return
    for _, temporary in CHECKPOINT_PIECES:
        (paths["dir"] / temporary).unlink(missing_ok=True)


def trained_steps(progress: Path) -> int:
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
    paths = checkpoint_paths(folder)
    if paths["dir"].exists():
        settle_checkpoint(paths)
    return paths["state"].exists()


def rng_state(model, env) -> dict[str, Any]:
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
        "env_rng": env.tc_generator_state,
        "action_space": model.action_space.np_random.bit_generator.state,
        "pending_tc": env.tc,
    }


def fsync_file(path: Path) -> None:
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
    paths = checkpoint_paths(folder)
    paths["dir"].mkdir(parents=True, exist_ok=True)
    staged = {piece: paths["dir"] / temporary for piece, temporary in CHECKPOINT_PIECES}
    model.save(staged["model"])
    model.save_replay_buffer(staged["buffer"])
    for piece in ("model", "buffer"):  # on disk before the marker commits them (power loss)
        fsync_file(staged[piece])
    state = {**rng_state(model, env), **extra}
    atomic_write_bytes(staged["state"], pickle.dumps(state))
    atomic_write_text(paths["commit"], json.dumps({"num_timesteps": int(model.num_timesteps)}))
    install_checkpoint(paths)


def load_checkpoint(folder: Path, env, run: RunSpec):
    """(model, state) from the run's checkpoint; a clear error if it is unusable."""
    import torch

    from distgprl.agents.sac import RegularisedSAC

    paths = checkpoint_paths(folder)
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
    env.tc_generator_state = state["env_rng"]
    model.action_space.np_random.bit_generator.state = state["action_space"]
    return model, state
