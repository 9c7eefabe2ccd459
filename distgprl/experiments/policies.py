"""The policies a trained run keeps: the actors of its best-so-far trained learning-curve
points (Algorithm 1's "best policy": among the points after the first SAC update,
`is_trained_point`, ranked by `curve_rank`, ties to the later point; the untrained step-0
point never qualifies, its curve success is recorded beside, `BestSelection`) and the loading
of a trained run's final or best policy (`load_trained_policy`)."""

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
    as pre-registered (docs/findings/protocol.md, rule 6): by the success rate on the
    learning-curve TCs alone; equal ones go to the later point (`best_curve_row`). The curve
    TCs are drawn from their own stream, disjoint from the evaluation TCs, so selecting on
    them and evaluating on the evaluation TCs is an honest model selection."""
    return (float(row["success_rate"]),)


def is_trained_point(row: dict[str, Any], learning_starts: int) -> bool:
    """Whether the actor of learning-curve point ``row`` has had at least one SAC update:
    its step s (``model.num_timesteps`` when the point was recorded) exceeds
    ``learning_starts``.

    SB3's off-policy loop (``OffPolicyAlgorithm.learn``) collects a rollout, which advances
    ``num_timesteps``, and then, if ``num_timesteps > learning_starts``, takes
    ``gradient_steps`` (>= 1, `distgprl.config`) gradient steps, before it checks whether to
    return; a curve point is evaluated after ``learn`` returned at step s. So the actor of
    a point at s > learning_starts has had at least one update (s - learning_starts of them
    with ``train_freq = gradient_steps = 1``, the presets'), and one at s <= learning_starts
    is still the initial actor: step 0 never qualifies.
    """
    return int(row["step"]) > int(learning_starts)


def untrained_curve_row(rows: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The step-0 learning-curve point (the untrained actor's), None if ``rows`` has none."""
    return next((row for row in rows if int(row["step"]) == 0), None)


def best_curve_row(
    rows: list[dict[str, Any]], learning_starts: int, folder: Path | str
) -> dict[str, Any]:
    """The best trained learning-curve point: among the points after the first SAC update
    (`is_trained_point`), the highest `curve_rank`, the latest of equal ones (``rows`` in
    the order of their steps, as ``progress.csv`` holds them).

    Raises:
        UserInputError: no point after the first update (one line naming ``folder``, the
            run folder): Algorithm 1's best policy must be a trained one.
    """
    trained = [row for row in rows if is_trained_point(row, learning_starts)]
    if not trained:
        steps = ", ".join(str(row["step"]) for row in rows) or "none"
        raise UserInputError(
            f"{folder}: no learning-curve point after the first SAC update (curve steps: "
            f"{steps}; a trained point needs step > learning_starts = {learning_starts}), so "
            "it has no trained best policy; train the run past learning_starts"
        )
    best = trained[0]
    for row in trained[1:]:
        if curve_rank(row) >= curve_rank(best):  # a tie goes to the later point
            best = row
    return best


@dataclass(frozen=True)
class BestSelection:
    """Algorithm 1's best policy of one run (`select_best`) and how it compares with the
    untrained actor.

    Attributes:
        row: the selected trained learning-curve point (`best_curve_row`).
        learning_starts: the run's SB3 ``learning_starts`` (steps) the selection used.
        beats_untrained: whether its `curve_rank` is strictly above the step-0 point's (a
            tie does not beat it); None where the curve has no step-0 point.
        untrained_curve_success_rate: the step-0 point's curve success (None: no such point).
    """

    row: dict[str, Any]
    learning_starts: int
    beats_untrained: bool | None
    untrained_curve_success_rate: float | None

    @property
    def step(self) -> int:
        """The selected point's step (> learning_starts)."""
        return int(self.row["step"])

    def record(self) -> dict[str, Any]:
        """The comparison with the untrained actor as `SHIPPED_POLICY_RECORD` and the
        best-policy summary record it."""
        return {
            "learning_starts": self.learning_starts,
            "beats_untrained": self.beats_untrained,
            "untrained_curve_success_rate": self.untrained_curve_success_rate,
        }


def select_best(
    rows: list[dict[str, Any]], learning_starts: int, folder: Path | str
) -> BestSelection:
    """`best_curve_row` of ``rows`` with its comparison against the step-0 point (raises as
    `best_curve_row` does where no point is trained)."""
    best = best_curve_row(rows, learning_starts, folder)
    untrained = untrained_curve_row(rows)
    if untrained is None:
        return BestSelection(best, int(learning_starts), None, None)
    beats = curve_rank(best) > curve_rank(untrained)
    return BestSelection(best, int(learning_starts), beats, float(untrained["success_rate"]))


def run_learning_starts(folder: Path) -> int:
    """The SB3 ``learning_starts`` the run in ``folder`` was trained with (its
    ``config.json``).

    Raises:
        UserInputError: no ``config.json``, or one without ``run.config.sac.learning_starts``.
    """
    path = folder / "config.json"
    if not path.exists():
        raise UserInputError(f"{path}: missing; the run's learning_starts is not known")
    value = read_json(path).get("run", {}).get("config", {}).get("sac", {}).get("learning_starts")
    if value is None:
        raise UserInputError(f"{path}: no run.config.sac.learning_starts")
    return int(value)


def run_best_selection(folder: Path) -> BestSelection:
    """`select_best` of the run in ``folder``: its ``progress.csv`` and ``config.json``
    (either missing: a `UserInputError` naming it)."""
    if not (folder / "progress.csv").exists():
        raise UserInputError(f"{folder / 'progress.csv'}: missing; the run has no learning curve")
    _, curve = read_csv(folder / "progress.csv")
    return select_best(curve, run_learning_starts(folder), folder)


def beats_every_earlier(
    earlier: list[dict[str, Any]], row: dict[str, Any], learning_starts: int
) -> bool:
    """Whether learning-curve point ``row`` is trained (`is_trained_point`) and ranks at
    least as high as every trained point of ``earlier`` (`curve_rank`; the first trained
    point does): training keeps its actor then, so the point `best_curve_row` selects (a tie
    goes to the later one) always has its actor, and no untrained actor is ever kept."""
    if not is_trained_point(row, learning_starts):
        return False
    ranks = (curve_rank(p) for p in earlier if is_trained_point(p, learning_starts))
    best_before = max(ranks, default=None)
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
"""The actor Table I evaluates (Algorithm 1's best policy), committed with a run's small
files (weights only: no critic, optimiser state or replay buffer); its step (> learning_starts),
SHA-256 and comparison with the untrained step-0 point (``beats_untrained``,
``untrained_curve_success_rate``) are in `SHIPPED_POLICY_RECORD`."""

SHIPPED_POLICY_RECORD = "policy_best.json"


def ship_best_policy(folder: Path) -> Path:
    """Copy a finished run's best trained learning-curve actor (`run_best_selection`: its
    ``progress.csv`` and ``config.json``; kept by training in the checkpoint folder) into the
    run folder as `SHIPPED_POLICY`, and record its step (> learning_starts), size, SHA-256
    and its comparison with the untrained step-0 point (`BestSelection.record`:
    ``beats_untrained``, ``untrained_curve_success_rate``) in `SHIPPED_POLICY_RECORD`
    (versioned JSON), so the policy survives the machine that trained it. The weights are
    written first, the record after (atomic both).

    Returns:
        The shipped weights' path.

    Raises:
        UserInputError: the run has no trained curve point, or the selected point's kept
            actor is missing; nothing is written then.
    """
    from distgprl.io import file_sha256
    from distgprl.schema import write_json

    selection = run_best_selection(folder)
    step = selection.step
    source = curve_policy_path(folder, step)
    if not source.exists():
        raise UserInputError(f"{source}: the best curve point (step {step}) has no kept actor")
    target = folder / SHIPPED_POLICY
    atomic_write_bytes(target, source.read_bytes())
    record: dict[str, Any] = {"policy": "best", "step": step, "bytes": target.stat().st_size}
    record["sha256"] = file_sha256(target)
    record["curve_success_rate"] = float(selection.row["success_rate"])
    record.update(selection.record())
    write_json(folder / SHIPPED_POLICY_RECORD, record, kind="policy")
    return target


def ship_if_missing(folder: Path) -> Path | None:
    """`ship_best_policy` for a finished run that does not ship its best actor yet and whose
    kept curve actor is on this machine; None where there is nothing to do or nothing to
    ship from (its checkpoints are on another machine, or it has no trained curve point:
    training said so when it skipped the best-policy evaluation)."""
    if (folder / SHIPPED_POLICY_RECORD).exists() or not (folder / "progress.csv").exists():
        return None
    try:
        step = run_best_selection(folder).step
    except UserInputError:  # no trained curve point (or no config.json): nothing to ship
        return None
    if not curve_policy_path(folder, step).exists():
        return None
    return ship_best_policy(folder)


@dataclass(frozen=True)
class TrainedPolicy:
    """A trained run's policy, loaded by `load_trained_policy`.

    Attributes:
        run: the run as it was trained (with its ``--steps``, if it was trained with them).
        model: the `RegularisedSAC` holding the policy (for ``policy="best"``, with the
            actor of the selected learning-curve point).
        selected: for ``policy="best"``: ``policy``, ``policy_step``, the selected
            point's curve figures and its comparison with the untrained step-0 point
            (`BestSelection.record`; what the summary records); else empty.
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


def _selected(selection: BestSelection) -> dict[str, Any]:
    """What a best-policy summary records of the selection."""
    best = selection.row
    return {
        "policy": "best",
        "policy_step": selection.step,
        "curve_success_rate": float(best["success_rate"]),
        "curve_collision_rate": float(best["collision_rate"]),
        "curve_mean_return": float(best["mean_return"]),
        **selection.record(),
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
    (`verified_shipped_policy`) and its step is the run's best curve point. The best policy
    is the best trained curve point (`select_best`, with the run's ``learning_starts``): a
    run without one is a `UserInputError` naming its folder. The final policy is not
    shipped: without ``model.zip`` it is an error naming what to do.
    """
    task, method, seed, preset = run.task, run.method.name, run.seed, run.config.preset
    model_path = folder / "model.zip"
    shipped = folder / SHIPPED_POLICY
    train = f"`distgprl train --method {method} --task {task} --seed {seed} --preset {preset}`"
    if policy == "best":
        if not (folder / "progress.csv").exists():
            raise UserInputError(f"{folder}: no progress.csv (no learning curve); run {train}")
        _, curve = read_csv(folder / "progress.csv")
        best = select_best(curve, run.config.sac.learning_starts, folder)
        step = best.step
        if model_path.exists() and curve_policy_path(folder, step).exists():
            run = _as_trained(run, folder, model_path)
            model = load_model(model_path, env, task, method)
            load_curve_policy(folder, model, step)
            return TrainedPolicy(run, model, _selected(best))
        if shipped.exists() or (folder / SHIPPED_POLICY_RECORD).exists():
            return _load_shipped(run, folder, env, best)
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


def _load_shipped(run: RunSpec, folder: Path, env, best: BestSelection) -> TrainedPolicy:
    """The run's shipped best actor in a fresh `RegularisedSAC` of the run's configuration,
    without its regulariser (its critics untrained and unused: only the actor acts)."""

    from distgprl.experiments.factories import make_agent

    path, record = verified_shipped_policy(folder)
    step = best.step
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
