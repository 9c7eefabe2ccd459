"""The policies a trained run keeps: the actors of its best-so-far learning-curve points
(Algorithm 1's "best policy", ranked by `curve_rank`, ties to the later point) and the
loading of a trained run's final or best policy (`load_trained_policy`)."""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from distgprl.errors import UserInputError
from distgprl.experiments.checkpoints import checkpoint_dir
from distgprl.experiments.factories import load_model
from distgprl.identity import RunSpec, resolve_run
from distgprl.io import atomic_write_bytes
from distgprl.schema import read_csv, read_json


def curve_policy_dir(folder: Path) -> Path:
    """Where a run keeps the actors of its best-so-far learning-curve points (checkpoints)."""
    return checkpoint_dir(folder) / "curve_policies"


def curve_policy_path(folder: Path, step: int) -> Path:
    """The kept actor of the learning-curve point at ``step``."""
    return curve_policy_dir(folder) / f"step{int(step)}.pt"


def curve_rank(row: dict[str, Any]) -> tuple[float, ...]:
    """How learning-curve points are ordered when Algorithm 1's "best policy" is selected,
    as pre-registered (docs/FINDINGS.md "Protocol v6", rule 6): by the success rate on the
    learning-curve TCs alone; equal ones go to the later point (`best_curve_row`). The curve
    TCs are drawn from their own stream, disjoint from the evaluation TCs, so selecting on
    them and evaluating on the evaluation TCs is an honest model selection."""
    return (float(row["success_rate"]),)


def best_curve_row(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The best learning-curve point: the highest `curve_rank`, the latest of equal ones
    (``rows`` in the order of their steps, as ``progress.csv`` holds them)."""
    if not rows:
        raise UserInputError("no learning-curve points to select the best policy from")
    best = rows[0]
    for row in rows[1:]:
        if curve_rank(row) >= curve_rank(best):  # a tie goes to the later point
            best = row
    return best


def beats_every_earlier(earlier: list[dict[str, Any]], row: dict[str, Any]) -> bool:
    """Whether learning-curve point ``row`` ranks at least as high as every point of
    ``earlier`` (`curve_rank`; the first point does): training keeps its actor then, so the
    point `best_curve_row` selects (a tie goes to the later one) always has its actor."""
    best_before = max((curve_rank(point) for point in earlier), default=None)
    return best_before is None or curve_rank(row) >= best_before


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


def load_actor(model, path: Path, what: str) -> None:
    """Replace the model's actor by the weights saved at ``path`` (``what`` names them in the
    `UserInputError` raised if they cannot be loaded)."""
    import torch

    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
        model.actor.load_state_dict(state)
    except Exception as exc:
        raise UserInputError(
            f"{path}: cannot load the {what} ({type(exc).__name__}: {exc})"
        ) from None


def load_curve_policy(folder: Path, model, step: int) -> None:
    """Replace the model's actor by the kept learning-curve actor of ``step``."""
    path = curve_policy_path(folder, step)
    if not path.exists():
        raise UserInputError(
            f"{path}: the best learning-curve point (step {step}) has no kept policy: it was "
            "trained before training kept curve policies, or on another machine (they stay "
            "in the checkpoint folder of the machine that trained the run)"
        )
    load_actor(model, path, "curve policy")


SHIPPED_POLICY = "policy_best.pt"
"""The actor Table I evaluates (Algorithm 1's best policy), committed with a v6 run's small
files (weights only: no critic, optimiser state or replay buffer); its step and SHA-256 are in
`SHIPPED_POLICY_RECORD`."""

SHIPPED_POLICY_RECORD = "policy_best.json"


def ship_best_policy(folder: Path) -> Path:
    """Copy a finished run's best learning-curve actor (`best_curve_row` of its
    ``progress.csv``, kept by training in the checkpoint folder) into the run folder as
    `SHIPPED_POLICY`, and record its step, size and SHA-256 in `SHIPPED_POLICY_RECORD`
    (versioned JSON), so the policy survives the machine that trained it. A kept actor that is
    missing is a `UserInputError`; the record is written after the weights (atomic both).

    Returns:
        The shipped weights' path.
    """
    from distgprl.io import file_sha256
    from distgprl.schema import write_json

    _, curve = read_csv(folder / "progress.csv")
    step = int(best_curve_row(curve)["step"])
    source = curve_policy_path(folder, step)
    if not source.exists():
        raise UserInputError(f"{source}: the best curve point (step {step}) has no kept actor")
    target = folder / SHIPPED_POLICY
    atomic_write_bytes(target, source.read_bytes())
    record = {"policy": "best", "step": step, "bytes": target.stat().st_size}
    record["sha256"] = file_sha256(target)
    write_json(folder / SHIPPED_POLICY_RECORD, record, kind="policy")
    return target


def ship_if_missing(folder: Path) -> Path | None:
    """`ship_best_policy` for a finished run that does not ship its best actor yet and whose
    kept curve actor is on this machine; None where there is nothing to do or nothing to
    ship from (its checkpoints are on another machine)."""
    if (folder / SHIPPED_POLICY_RECORD).exists() or not (folder / "progress.csv").exists():
        return None
    _, curve = read_csv(folder / "progress.csv")
    if not curve or not curve_policy_path(folder, int(best_curve_row(curve)["step"])).exists():
        return None
    return ship_best_policy(folder)


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


def verified_shipped_policy(folder: Path) -> tuple[Path, dict[str, Any]]:
    """The run's shipped actor (`SHIPPED_POLICY`) and its record, after checking that its
    SHA-256 is the recorded one.

    Raises:
        UserInputError: the weights or the record is missing, or the hash does not match (a
            changed or damaged file is never loaded, and never silently retrained).
    """
    from distgprl.io import file_sha256

    path, record_path = folder / SHIPPED_POLICY, folder / SHIPPED_POLICY_RECORD
    missing = [p.name for p in (path, record_path) if not p.exists()]
    if missing:
        raise UserInputError(f"{folder}: no shipped policy ({' and '.join(missing)} missing)")
    record = read_json(record_path)
    digest = file_sha256(path)
    if digest != record.get("sha256"):
        raise UserInputError(
            f"{path}: SHA-256 {digest} does not match the {record.get('sha256')} recorded in "
            f"{record_path.name}: the shipped policy was changed or damaged; restore it "
            "(git checkout) or retrain the run"
        )
    return path, record


def _as_trained(run: RunSpec, folder: Path, what: Path) -> RunSpec:
    """``run`` with the configuration the run in ``folder`` was trained with (its
    ``total_steps`` included), which must still be what the code resolves (``what``: the file
    about to be loaded, for the error)."""
    task, method, seed, preset = run.task, run.method.name, run.seed, run.config.preset
    trained = read_json(folder / "config.json") if (folder / "config.json").exists() else {}
    steps = trained.get("run", {}).get("config", {}).get("run", {}).get("total_steps")
    if steps is not None and steps != run.config.run.total_steps:  # trained with --steps
        run = resolve_run(task, method, seed, preset, steps)
    recorded = trained.get("config_hash")
    if recorded != run.hash:
        raise UserInputError(
            f"{what}: trained with configuration {recorded}, the code now resolves "
            f"{run.hash} for this run; re-train it (evaluating would mislabel the model)"
        )
    return run


def _selected(best: dict[str, Any]) -> dict[str, Any]:
    return {
        "policy": "best",
        "policy_step": int(best["step"]),
        "curve_success_rate": float(best["success_rate"]),
        "curve_collision_rate": float(best["collision_rate"]),
        "curve_mean_return": float(best["mean_return"]),
    }


def load_trained_policy(run: RunSpec, folder: Path, env, policy: str = "final") -> TrainedPolicy:
    """Load the final (``policy="final"``, ``model.zip``) or best learning-curve
    (``policy="best"``) policy of the trained run in ``folder``.

    The run is taken with the configuration it was trained with (its ``total_steps``
    included), which must still be what the code resolves; a model of an older
    configuration, or one whose spaces do not match ``env``'s, is a `UserInputError`.

    The best policy comes from the checkpoint folder of the machine that trained the run
    (``model.zip`` and the kept curve actor) where they are, otherwise from the actor the run
    ships (`SHIPPED_POLICY`, committed with its small files: a fresh clone evaluates, renders
    and runs Table I's policy without training), after its SHA-256 is checked
    (`verified_shipped_policy`) and its step is the run's best curve point. The final policy
    is not shipped: without ``model.zip`` it is an error naming what to do.
    """
    task, method, seed, preset = run.task, run.method.name, run.seed, run.config.preset
    model_path = folder / "model.zip"
    shipped = folder / SHIPPED_POLICY
    train = f"`distgprl train --method {method} --task {task} --seed {seed} --preset {preset}`"
    if policy == "best":
        _, curve = read_csv(folder / "progress.csv")
        best = best_curve_row(curve)
        step = int(best["step"])
        if model_path.exists() and curve_policy_path(folder, step).exists():
            run = _as_trained(run, folder, model_path)
            model = load_model(model_path, env, task, method)
            load_curve_policy(folder, model, step)
            return TrainedPolicy(run, model, _selected(best))
        if shipped.exists() or (folder / SHIPPED_POLICY_RECORD).exists():
            return _load_shipped(run, folder, env, step, best)
        raise UserInputError(
            f"{folder}: neither the trained model with its kept curve actor (checkpoints stay "
            f"on the machine that trained the run) nor a shipped {SHIPPED_POLICY}; run {train}"
        )
    if not model_path.exists():
        ships = f" (it ships only its best policy, {SHIPPED_POLICY}: --policy best)"
        raise UserInputError(
            f"{model_path}: no trained model{ships if shipped.exists() else ''}; run {train} first"
        )
    run = _as_trained(run, folder, model_path)
    return TrainedPolicy(run, load_model(model_path, env, task, method), {})


def _load_shipped(
    run: RunSpec, folder: Path, env, step: int, best: dict[str, Any]
) -> TrainedPolicy:
    """The run's shipped best actor in a fresh `RegularisedSAC` of the run's configuration,
    without its regulariser (its critics untrained and unused: only the actor acts)."""

    from distgprl.experiments.factories import make_agent

    path, record = verified_shipped_policy(folder)
    if int(record.get("step", -1)) != step:
        raise UserInputError(
            f"{path}: shipped from curve step {record.get('step')}, but the run's best curve "
            f"point (progress.csv) is step {step}; re-ship it (experiments.policies."
            "ship_best_policy) on the machine that trained the run"
        )
    run = _as_trained(run, folder, path)
    model = make_agent(env, run, regularised=False)  # it only acts
    load_actor(model, path, "shipped policy")
    selected = _selected(best) | {
        "policy_source": SHIPPED_POLICY,
        "policy_sha256": record["sha256"],
    }
    return TrainedPolicy(run, model, selected)
