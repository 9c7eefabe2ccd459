"""A run's checkpoint (model, replay buffer and RNG state), saved as one transaction: a kill
at any point leaves either the previous checkpoint or the new one (`save_checkpoint`,
`settle_checkpoint`), and a resumed run continues exactly where it stopped
(`load_checkpoint`).

Two generations are kept: the newest in the checkpoint folder, the one before it in its
``previous/`` folder (hard links where the file system allows, so rotating copies nothing;
the disk holds up to two replay buffers). Each generation has a ``manifest.json``: its step
and the size and SHA-256 of each of its three files, written atomically after the files.
A resume verifies the newest generation against its manifest and loads it; a damaged one (a
file missing, truncated, empty, not matching its manifest or not loadable) is discarded and
the previous generation is tried; with none left the run restarts from step 0
(`CheckpointLoad.describe` says which, in one line)."""

from __future__ import annotations

import json
import os
import pickle
import random
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from distgprl.experiments.factories import make_agent
from distgprl.identity import RunSpec
from distgprl.io import atomic_write_bytes, atomic_write_text, file_sha256
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


#: The files of one checkpoint generation, by piece.
PIECE_FILES = {"model": "model.zip", "buffer": "replay_buffer.pkl", "state": "state.pkl"}

MANIFEST_NAME = "manifest.json"
"""A generation's manifest: ``{"format": 1, "num_timesteps": N, "files": {name: {"bytes":
size, "sha256": hex}}}`` over the three `PIECE_FILES`."""


def checkpoint_paths(folder: Path) -> dict[str, Path]:
    """The checkpoint's folder (``dir``), its newest generation's pieces (``model``,
    ``buffer``, ``state``) and ``manifest``, the commit marker (``commit``) of
    `save_checkpoint` and the folder of the generation before (``previous``)."""
    ckpt = checkpoint_dir(folder)
    return {
        "dir": ckpt,
        **{piece: ckpt / name for piece, name in PIECE_FILES.items()},
        "manifest": ckpt / MANIFEST_NAME,
        "commit": ckpt / "commit.json",
        "previous": ckpt / "previous",
    }


#: The checkpoint's pieces and the temporary names they are written under first.
CHECKPOINT_PIECES = (
    ("model", ".model.tmp.zip"),
    ("buffer", ".buffer.tmp.pkl"),
    ("state", ".state.tmp.pkl"),
)


def _read_manifest(path: Path) -> dict[str, Any] | None:
    """The manifest at ``path`` (None if absent, unreadable or not a manifest)."""
    try:
        manifest = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    if not isinstance(manifest, dict) or not isinstance(manifest.get("files"), dict):
        return None
    return manifest


def rotate_generations(paths: dict[str, Path]) -> None:
    """Make the newest generation the ``previous`` one (which it replaces), leaving its files
    in place for `install_checkpoint` to replace: they are linked (or copied) into a
    temporary folder that is then renamed to ``previous``."""
    staging, old = paths["dir"] / ".previous.tmp", paths["dir"] / ".previous.old"
    for leftover in (staging, old):  # of a rotation a kill interrupted
        shutil.rmtree(leftover, ignore_errors=True)
    staging.mkdir()
    for name in (*PIECE_FILES.values(), MANIFEST_NAME):
        source = paths["dir"] / name
        if source.exists():
            try:
                os.link(source, staging / name)
            except OSError:  # a file system without hard links
                shutil.copy2(source, staging / name)
    if paths["previous"].exists():
        paths["previous"].rename(old)
    staging.rename(paths["previous"])
    shutil.rmtree(old, ignore_errors=True)


def install_checkpoint(paths: dict[str, Path]) -> None:
    """Roll the committed checkpoint forward (idempotent): rotate the newest generation to
    ``previous`` unless that was done already, move every written piece into place, write
    the new manifest, then drop the commit marker.

    The commit marker holds the new manifest: the newest generation's manifest equal to it
    means the pieces are in place; the previous generation's manifest equal to the newest's
    means the rotation was done (pieces are replaced only after it)."""
    commit = _read_manifest(paths["commit"])  # None: a marker of a version before manifests
    current = _read_manifest(paths["manifest"])
    if commit is not None and current is not None and current != commit:
        if _read_manifest(paths["previous"] / MANIFEST_NAME) != current:
            rotate_generations(paths)
    for piece, temporary in CHECKPOINT_PIECES:
        staged = paths["dir"] / temporary
        if staged.exists():
            staged.replace(paths[piece])
    if commit is not None:
        atomic_write_text(paths["manifest"], json.dumps(commit, sort_keys=True))
    else:  # no manifest describes these pieces
        paths["manifest"].unlink(missing_ok=True)
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


def _generations(paths: dict[str, Path]) -> list[Path]:
    """The folders of the checkpoint generations that hold any piece, newest first."""
    return [
        directory
        for directory in (paths["dir"], paths["previous"])
        if any((directory / name).exists() for name in PIECE_FILES.values())
    ]


def has_checkpoint(folder: Path) -> bool:
    """Whether the run has a checkpoint to resume from, good or damaged (settling an
    interrupted save first)."""
    paths = checkpoint_paths(folder)
    if paths["dir"].exists():
        settle_checkpoint(paths)
    return bool(_generations(paths))


def checkpoint_step(folder: Path) -> int | None:
    """The step of the checkpoint a resume of the run would continue from, read without
    writing anything (a status report): the pending commit marker's (a save a kill
    interrupted after it committed), else the newest generation's manifest, else the
    previous generation's; None if the run has no checkpoint. A generation without a
    manifest (a format before manifests) counts with the step its state file records."""
    paths = checkpoint_paths(folder)
    pending = _read_manifest(paths["commit"])
    if pending is not None and "num_timesteps" in pending:
        return int(pending["num_timesteps"])
    for directory in _generations(paths):
        manifest = _read_manifest(directory / MANIFEST_NAME)
        if manifest is not None and "num_timesteps" in manifest:
            return int(manifest["num_timesteps"])
        try:
            state = pickle.loads((directory / PIECE_FILES["state"]).read_bytes())
            return int(state["num_timesteps"])
        except (OSError, EOFError, pickle.UnpicklingError, KeyError, TypeError, ValueError):
            continue  # damaged: a resume falls back to the generation before it
    return None


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

    The three pieces are written under temporary names, then a commit marker holding their
    manifest is written atomically, then the newest generation becomes ``previous``, the
    pieces are moved into place, the manifest is written and the marker removed
    (`install_checkpoint`)."""
    paths = checkpoint_paths(folder)
    paths["dir"].mkdir(parents=True, exist_ok=True)
    staged = {piece: paths["dir"] / temporary for piece, temporary in CHECKPOINT_PIECES}
    model.save(staged["model"])
    model.save_replay_buffer(staged["buffer"])
    for piece in ("model", "buffer"):  # on disk before the marker commits them (power loss)
        fsync_file(staged[piece])
    state = {**rng_state(model, env), **extra}
    atomic_write_bytes(staged["state"], pickle.dumps(state))
    manifest = {
        "format": 1,
        "num_timesteps": int(model.num_timesteps),
        "files": {
            PIECE_FILES[piece]: {
                "bytes": staged[piece].stat().st_size,
                "sha256": file_sha256(staged[piece]),
            }
            for piece in PIECE_FILES
        },
    }
    atomic_write_text(paths["commit"], json.dumps(manifest, sort_keys=True))
    install_checkpoint(paths)


@dataclass(frozen=True)
class CheckpointDamage:
    """A checkpoint file a run cannot resume from.

    Attributes:
        file: the damaged (or missing) file.
        reason: why, one line.
    """

    file: Path
    reason: str

    def describe(self) -> str:
        """``"<file> <reason>"``."""
        return f"{self.file} {self.reason}"


class _Damaged(Exception):
    """A checkpoint generation is unusable; ``damage`` says which file and why."""

    def __init__(self, file: Path, reason: str):
        super().__init__(f"{file} {reason}")
        self.damage = CheckpointDamage(file, " ".join(reason.split()))


@dataclass(frozen=True)
class CheckpointLoad:
    """What `load_checkpoint` found.

    Attributes:
        model: the resumed model, or None if no generation was usable.
        state: the loaded RNG and bookkeeping state (empty without ``model``).
        damaged: the damaged generations' first damaged files, newest first (empty: the
            newest checkpoint was good).
    """

    model: Any
    state: dict[str, Any]
    damaged: tuple[CheckpointDamage, ...]

    def describe(self, folder: Path, reached: int) -> str:
        """The one line a resume prints when a checkpoint was damaged (empty if none was):
        which file, and whether the run resumed from the previous checkpoint or restarts
        (``reached``: the step the run's learning curve had reached)."""
        if not self.damaged:
            return ""
        first = self.damaged[0].describe()
        if self.model is not None:
            return (
                f"warning: {folder}: damaged checkpoint, {first}; resumed from the previous "
                f"checkpoint (step {self.model.num_timesteps})"
            )
        also = "".join(f"; so is the previous one, {d.describe()}" for d in self.damaged[1:])
        return (
            f"warning: {folder}: damaged checkpoint, {first}{also}; no good checkpoint is "
            f"left, so the run (which had reached step {reached}) restarts from step 0"
        )


def _verify(directory: Path, manifest: dict[str, Any]) -> None:
    """Raise `_Damaged` for the first of the generation's files that its manifest does not
    describe exactly (missing, another size, another SHA-256)."""
    manifest_path = directory / MANIFEST_NAME
    for name in PIECE_FILES.values():
        record = manifest["files"].get(name)
        if not isinstance(record, dict) or not {"bytes", "sha256"} <= set(record):
            raise _Damaged(manifest_path, f"has no size and SHA-256 of {name}")
        path = directory / name
        if not path.is_file():
            raise _Damaged(path, "is missing")
        size = path.stat().st_size
        if size != record["bytes"]:
            what = "is empty (0 bytes)" if size == 0 else f"has {size} bytes"
            raise _Damaged(path, f"{what}, its manifest records {record['bytes']}")
        digest = file_sha256(path)
        if digest != record["sha256"]:
            raise _Damaged(
                path,
                f"has SHA-256 {digest[:12]}..., its manifest records {record['sha256'][:12]}...",
            )


def _load_generation(directory: Path, env, strict: bool):
    """(model, state) of one checkpoint generation, verified against its manifest (a
    generation written before manifests, ``strict`` False, only by loading); `_Damaged`
    naming the first unusable file otherwise."""
    from distgprl.agents.sac import RegularisedSAC

    files = {piece: directory / name for piece, name in PIECE_FILES.items()}
    manifest_path = directory / MANIFEST_NAME
    manifest = _read_manifest(manifest_path)
    if manifest is not None:
        _verify(directory, manifest)
    elif manifest_path.exists():
        raise _Damaged(manifest_path, "is not a readable checkpoint manifest")
    elif strict:
        raise _Damaged(manifest_path, "is missing (the checkpoint was being replaced)")
    for path in files.values():
        if not path.is_file():
            raise _Damaged(path, "is missing")

    def unreadable(exc: Exception) -> str:
        return f"cannot be loaded ({type(exc).__name__}: {exc})"

    try:
        state = pickle.loads(files["state"].read_bytes())
    except Exception as exc:  # an unreadable pickle raises almost anything
        raise _Damaged(files["state"], unreadable(exc)) from None
    if not isinstance(state, dict) or not isinstance(state.get("num_timesteps"), int):
        raise _Damaged(files["state"], "is not a checkpoint state")
    try:
        model = RegularisedSAC.load_saved(files["model"], env=env)
    except Exception as exc:  # any unloadable model makes the generation unusable
        raise _Damaged(files["model"], unreadable(exc)) from None
    try:
        model.load_replay_buffer(files["buffer"])
    except Exception as exc:
        raise _Damaged(files["buffer"], unreadable(exc)) from None
    if model.num_timesteps != state["num_timesteps"]:
        raise _Damaged(
            files["model"],
            f"is from step {model.num_timesteps} and {files['state'].name} from step "
            f"{state['num_timesteps']}: pieces of different checkpoints",
        )
    needed = min(state["num_timesteps"], model.buffer_size)
    held = model.replay_buffer.size() if model.replay_buffer is not None else 0
    if held < needed:
        raise _Damaged(files["buffer"], f"holds {held} transitions, the checkpoint needs {needed}")
    return model, state


def verify_checkpoints(folder: Path) -> list[CheckpointDamage]:
    """The first damaged file of each of the run's checkpoint generations that does not
    match its manifest, newest first (empty: every generation on disk matches; a
    generation without a manifest, written before manifests, is not checked here)."""
    paths = checkpoint_paths(folder)
    damaged = []
    for directory in _generations(paths):
        manifest_path = directory / MANIFEST_NAME
        manifest = _read_manifest(manifest_path)
        if manifest is None:
            if manifest_path.exists():
                damaged.append(CheckpointDamage(manifest_path, "is not a readable manifest"))
            continue
        try:
            _verify(directory, manifest)
        except _Damaged as error:
            damaged.append(error.damage)
    return damaged


def _discard_newest(paths: dict[str, Path]) -> None:
    """Remove the damaged newest generation, manifest first, so that a later save never
    rotates it over the good previous one (`install_checkpoint` rotates only a generation
    with a manifest)."""
    for path in (paths["manifest"], *(paths[piece] for piece in PIECE_FILES)):
        path.unlink(missing_ok=True)


def load_checkpoint(folder: Path, env, run: RunSpec) -> CheckpointLoad:
    """The run's newest good checkpoint generation, ready to train on (`CheckpointLoad`).

    The newest generation is tried first, then the previous one; a damaged newest one is
    removed once the previous one loads. The newest generation must have a manifest when a
    previous one exists (else it is the remnant of a save or a removal a kill interrupted).
    """
    import torch

    paths = checkpoint_paths(folder)
    damaged: list[CheckpointDamage] = []
    loaded = None
    for directory in _generations(paths):
        strict = directory == paths["dir"] and paths["previous"].is_dir()
        try:
            loaded = _load_generation(directory, env, strict)
        except _Damaged as error:
            damaged.append(error.damage)
            continue
        if directory != paths["dir"]:
            _discard_newest(paths)
        break
    if loaded is None:
        return CheckpointLoad(None, {}, tuple(damaged))
    model, state = loaded
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
    return CheckpointLoad(model, state, tuple(damaged))
