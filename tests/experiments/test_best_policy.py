"""Algorithm 1's "best policy": curve policies kept in training, selected, evaluated."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from distgprl.cli import app
from distgprl.errors import UserInputError
from distgprl.experiments import policies, runner, training
from distgprl.experiments.results import read_csv, read_json

STEPS = 240  # the `ci` preset shortened: curve points at 0, 120, 240


def train(root, steps=STEPS, **kwargs):
    return runner.train_run(
        "dcp", "dist-gprl", 0, preset="ci", steps=steps, root=root, show_progress=False, **kwargs
    )


def kept_steps(folder) -> list[int]:
    directory = runner.curve_policy_dir(folder)
    return sorted(int(p.stem.removeprefix("step")) for p in directory.glob("step*.pt"))


def kept_actor(folder, step):
    import torch

    state = torch.load(runner.curve_policy_path(folder, step), weights_only=True)
    return [value.numpy() for value in state.values()]


def final_actor(folder):
    from distgprl.agents.sac import RegularisedSAC

    model = RegularisedSAC.load_saved(folder / "model.zip")
    return [value.numpy() for value in model.actor.state_dict().values()]


def row(success, collision, ret, step=0):
    return {"step": step, "success_rate": success, "collision_rate": collision, "mean_return": ret}


def test_best_point_is_the_highest_curve_success_ties_to_the_later_point():
    """As pre-registered (FINDINGS "Protocol v6", rule 6): the highest curve success alone
    (collision rate and return do not break ties), and of equal ones the later point."""
    rows = [
        row(0.5, 0.0, 9.0, 0),
        row(0.8, 0.0, 99.0, 1),  # the same success with fewer collisions and more return...
        row(0.8, 0.4, 1.0, 2),
        row(0.8, 0.6, 0.0, 3),  # ...loses to the latest point of that success
        row(0.7, 0.0, 99.0, 4),
    ]
    assert runner.best_curve_row(rows)["step"] == 3
    as_read = [{k: str(v) for k, v in r.items()} for r in rows]  # progress.csv gives strings
    assert runner.best_curve_row(as_read)["step"] == "3"
    assert runner.best_curve_row(rows[:1])["step"] == 0
    assert runner.best_curve_row([row(0.3, 0, 0, s) for s in range(4)])["step"] == 3  # all tie
    assert runner.best_curve_row([row(0.9, 0, 0, 0), row(0.3, 0, 0, 1)])["step"] == 0
    with pytest.raises(UserInputError, match="no learning-curve points"):
        runner.best_curve_row([])


def test_a_point_is_kept_when_it_ranks_at_least_as_high_as_every_earlier_one():
    """The first point is kept; a later one if it ranks at least as high as every earlier
    one: a tie keeps the later actor too, as `best_curve_row` selects the later of equal
    points, so the selected point always has its actor."""
    first, better, tie = row(0.5, 0.0, 1.0, 0), row(0.6, 0.0, 0.0, 1), row(0.6, 0.9, -5.0, 2)
    assert policies.beats_every_earlier([], first)
    assert policies.beats_every_earlier([first], better)
    assert policies.beats_every_earlier([first, better], tie)
    assert not policies.beats_every_earlier([better], first)
    curve = [row(*point, step) for step, point in enumerate([(0.5, 0, 0), (0.4, 0, 0)])]
    curve += [row(0.6, 0.0, 0.0, 2), row(0.6, 0.9, -5.0, 3), row(0.55, 0.0, 0.0, 4)]
    kept = [r["step"] for i, r in enumerate(curve) if policies.beats_every_earlier(curve[:i], r)]
    assert kept == [0, 2, 3] and runner.best_curve_row(curve)["step"] == kept[-1]


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A 240-step dist-gprl run (curve points and checkpoints at 0/120/240 and 120/240)."""
    return train(tmp_path_factory.mktemp("run"), evaluate_after=False)


def test_a_curve_policy_is_kept_exactly_where_a_point_beats_every_earlier_one(trained):
    _, progress = read_csv(trained / "progress.csv")
    expected, best = [], None
    for r in progress:
        if best is None or runner.curve_rank(r) >= best:
            expected.append(int(r["step"]))
            best = runner.curve_rank(r)
    assert kept_steps(trained) == expected
    assert expected[0] == 0


@pytest.fixture(scope="module")
def ranked_by_step(tmp_path_factory):
    """A 240-step run (evaluated) whose curve ranking always improves (later is better)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(policies, "curve_rank", lambda r: (float(r["step"]),))
        root = tmp_path_factory.mktemp("ranked")
        folder = train(root)
    return root, folder


def test_every_kept_actor_is_the_actor_of_its_step(ranked_by_step):
    """With a ranking that always improves, every point is kept: the last one is the final
    model's actor, the first one the untrained actor, and they differ."""
    _, folder = ranked_by_step
    assert kept_steps(folder) == [0, 120, 240]
    for kept, final in zip(kept_actor(folder, 240), final_actor(folder), strict=True):
        np.testing.assert_array_equal(kept, final)
    assert any(
        not np.array_equal(a, b)
        for a, b in zip(kept_actor(folder, 0), kept_actor(folder, 240), strict=True)
    )


def test_a_killed_and_resumed_run_keeps_the_same_curve_policies(
    tmp_path, kill_at_the_first_checkpoint, trained
):
    """Killed after its step-120 checkpoint; a curve policy of a later point that the resume
    discards (left by a kill between that point and the next checkpoint) is dropped, and the
    resumed run ends with the same kept policies, bit for bit, as the uninterrupted one."""
    kill_at_the_first_checkpoint(tmp_path)
    folder = runner.run_dir(tmp_path, "ci", "dcp", "dist-gprl", 0)
    stale = runner.curve_policy_path(folder, 180)
    stale.write_bytes(b"a point the resume discards")
    resumed = train(tmp_path, evaluate_after=False, resume=True)
    assert not stale.exists()
    assert kept_steps(resumed) == kept_steps(trained)
    for step in kept_steps(trained):
        for a, b in zip(kept_actor(resumed, step), kept_actor(trained, step), strict=True):
            np.testing.assert_array_equal(a, b)


def test_best_policy_evaluation_writes_its_own_files_and_records_the_selection(
    ranked_by_step, monkeypatch
):
    """The best point here is the last (ranking by step): its evaluation equals the final
    policy's episode by episode, under the ``_best`` names, with the selection recorded."""
    root, folder = ranked_by_step
    monkeypatch.setattr(policies, "curve_rank", lambda r: (float(r["step"]),))
    final_text = (folder / "evaluation.csv").read_text()
    summary = runner.evaluate_run(
        "dcp", "dist-gprl", 0, "ci", root=root, show_progress=False, policy="best"
    )
    assert (folder / "evaluation.csv").read_text() == final_text
    assert summary["policy"] == "best" and summary["policy_step"] == 240
    assert read_json(folder / "summary_best.json")["summary"]["policy_step"] == 240
    _, best_rows = read_csv(folder / "evaluation_best.csv")
    _, final_rows = read_csv(folder / "evaluation.csv")
    compared = ("success", "collision", "min_clearance", "return")
    assert [[r[k] for k in compared] for r in best_rows] == [
        [r[k] for k in compared] for r in final_rows
    ]


def test_best_policy_evaluation_loads_the_selected_points_actor(tmp_path, monkeypatch):
    """Ranking earliest first selects the untrained step-0 actor: the evaluated policy is
    that actor (its returns differ from the final policy's), not the final one."""
    monkeypatch.setattr(policies, "curve_rank", lambda r: (-float(r["step"]),))
    folder = train(tmp_path)
    loaded = {}
    original = policies.load_curve_policy

    def spy(folder_, model, step):
        original(folder_, model, step)
        loaded["step"] = step
        loaded["actor"] = [v.numpy().copy() for v in model.actor.state_dict().values()]

    monkeypatch.setattr(policies, "load_curve_policy", spy)
    summary = runner.evaluate_run(
        "dcp", "dist-gprl", 0, "ci", root=tmp_path, show_progress=False, policy="best"
    )
    assert loaded["step"] == 0 and summary["policy_step"] == 0
    for a, b in zip(loaded["actor"], kept_actor(folder, 0), strict=True):
        np.testing.assert_array_equal(a, b)
    _, best_rows = read_csv(folder / "evaluation_best.csv")
    _, final_rows = read_csv(folder / "evaluation.csv")
    assert [r["return"] for r in best_rows] != [r["return"] for r in final_rows]


def test_training_evaluates_the_best_policy_beside_the_final_one(ranked_by_step):
    _, folder = ranked_by_step
    summary = read_json(folder / "summary_best.json")["summary"]
    assert summary["policy_step"] == 240
    assert len(read_csv(folder / "evaluation_best.csv")[1]) == summary["episodes"]


def test_training_skips_the_best_policy_evaluation_it_cannot_do_and_says_so(
    tmp_path, monkeypatch, capsys
):
    """A run whose best point has no kept actor (trained before they were kept) still
    finishes and is evaluated; only the best-policy evaluation is skipped, with a note."""
    monkeypatch.setattr(training, "save_curve_policy", lambda folder, model: None)
    folder = train(tmp_path, steps=120)
    assert (folder / "done.json").exists() and (folder / "summary.json").exists()
    assert not (folder / "summary_best.json").exists()
    assert "best-policy evaluation is skipped" in capsys.readouterr().err


def test_a_best_point_without_its_kept_policy_is_a_clear_error(tmp_path):
    """Runs trained before curve policies were kept (or on another machine), that ship no
    best actor either, are refused, naming what is missing."""
    folder = train(tmp_path, steps=120, evaluate_after=False)
    for path in runner.curve_policy_dir(folder).glob("*.pt"):
        path.unlink()
    with pytest.raises(UserInputError, match=r"neither the trained model with its kept curve"):
        runner.evaluate_run(
            "dcp", "dist-gprl", 0, "ci", root=tmp_path, show_progress=False, policy="best"
        )


def test_bad_policy_choices_are_clear_errors(tmp_path):
    with pytest.raises(UserInputError, match="not trained"):
        runner.evaluate_run("dcp", "demo", 0, "ci", root=tmp_path, policy="best")
    with pytest.raises(UserInputError, match="unknown policy 'worst'"):
        runner.evaluate_run("dcp", "demo", 0, "ci", root=tmp_path, policy="worst")


def test_file_names_keep_the_final_policys_and_tag_the_best():
    assert runner.evaluation_file_names() == ("evaluation.csv", "summary.json")
    assert runner.evaluation_file_names(1000) == ("evaluation_n1000.csv", "summary_n1000.json")
    assert runner.evaluation_file_names(None, "best") == (
        "evaluation_best.csv",
        "summary_best.json",
    )
    assert runner.evaluation_file_names(1000, "best") == (
        "evaluation_best_n1000.csv",
        "summary_best_n1000.json",
    )


def test_cli_evaluates_the_best_policy(trained):
    root = trained.parents[3]
    result = CliRunner().invoke(
        app,
        [
            "evaluate",
            "--method",
            "dist-gprl",
            "--task",
            "dcp",
            "--preset",
            "ci",
            "--root",
            str(root),
            "--policy",
            "best",
        ],
    )
    assert result.exit_code == 0, result.output
    assert '"policy": "best"' in result.output
    assert (trained / "summary_best.json").exists()


@pytest.mark.parametrize("task", ["dcp", "dbm"])
def test_the_learning_curve_tcs_are_disjoint_from_the_evaluation_tcs(task):
    """The best policy is chosen on the learning-curve TCs (FINDINGS "Protocol v6", rule 6),
    so none of them may be an evaluation TC: compared exactly (every offset, as floats), the
    `paper` preset's 50 curve TCs — and the stream's first 1000, more than any preset
    draws — share none with the 100 evaluation TCs, nor with the first 1000 (the
    supplementary evaluations)."""
    from distgprl.config import load_config
    from distgprl.sim.tasks import get_task
    from distgprl.sim.tasks.base import TaskConfig

    def offsets(tc: TaskConfig) -> tuple[float, ...]:
        return (*tc.object_offset, *tc.obstacle_offset)

    spec = get_task(task)
    run = load_config("paper", task).run  # as training and evaluation resolve it
    assert (run.curve_episodes, run.eval_episodes) == (50, 100)
    curve = [offsets(tc) for tc in spec.training_curve_tcs(run.curve_episodes)]
    evaluation = [offsets(tc) for tc in spec.evaluation_tcs(run.eval_episodes)]
    assert len(set(curve)) == 50 and len(set(evaluation)) == 100  # draws, not one repeated TC
    assert not set(curve) & set(evaluation)
    long_curve = {offsets(tc) for tc in spec.training_curve_tcs(1000)}
    long_evaluation = {offsets(tc) for tc in spec.evaluation_tcs(1000)}
    assert set(curve) <= long_curve and set(evaluation) <= long_evaluation  # prefixes
    assert not long_curve & long_evaluation


def test_ship_best_policy_copies_the_best_actor_with_its_hash(tmp_path, monkeypatch):
    """`ship_best_policy` puts the kept actor of the best curve point (ties: the later) into
    the run folder, byte for byte, with its step and SHA-256 recorded; a missing kept actor
    is a `UserInputError`, not a silently different policy."""
    import hashlib

    from distgprl.errors import UserInputError
    from distgprl.experiments import policies
    from distgprl.experiments.results import write_csv
    from distgprl.experiments.runner import PROGRESS_FIELDS
    from distgprl.schema import read_json

    monkeypatch.setenv("DISTGPRL_CHECKPOINT_ROOT", str(tmp_path / "ckpt"))
    folder = tmp_path / "run"
    rows = []
    for step, success in ((0, 0.1), (100, 0.6), (200, 0.6), (300, 0.2)):
        row = dict.fromkeys(PROGRESS_FIELDS, "")
        row.update(step=step, success_rate=success, collision_rate=0.0)
        rows.append(row)
    write_csv(folder / "progress.csv", rows, PROGRESS_FIELDS)
    with pytest.raises(UserInputError, match="step 200"):
        policies.ship_best_policy(folder)
    kept = policies.curve_policy_path(folder, 200)
    kept.parent.mkdir(parents=True)
    kept.write_bytes(b"actor weights")
    shipped = policies.ship_best_policy(folder)
    assert shipped == folder / policies.SHIPPED_POLICY
    assert shipped.read_bytes() == b"actor weights"
    record = read_json(folder / policies.SHIPPED_POLICY_RECORD)
    assert record["step"] == 200 and record["bytes"] == len(b"actor weights")
    assert record["sha256"] == hashlib.sha256(b"actor weights").hexdigest()
