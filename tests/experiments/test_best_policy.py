"""Algorithm 1's "best policy": curve policies kept in training, selected, evaluated. The
best policy is a trained one (protocol v8, rule 2): only curve points after the first SAC
update (step > learning_starts) qualify, the step-0 point never does."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from distgprl.cli import app
from distgprl.errors import UserInputError
from distgprl.experiments import policies, training
from distgprl.experiments.evaluation import evaluate_run
from distgprl.experiments.policies import (
    best_curve_row,
    curve_policy_dir,
    curve_policy_path,
    curve_rank,
)
from distgprl.experiments.training import train_run
from distgprl.schema import evaluation_file_names, read_csv, read_json, run_dir, write_json

STEPS = 240  # the `ci` preset shortened: curve points at 0, 120, 240
CI_LEARNING_STARTS = 60  # the `ci` preset's sac.learning_starts: 120 and 240 are trained
LS = 50  # learning_starts of the synthetic curves below (steps 0, 100, 200, ...)


def train(root, steps=STEPS, **kwargs):
    return train_run(
        "dcp", "dist-gprl", 0, preset="ci", steps=steps, root=root, show_progress=False, **kwargs
    )


def kept_steps(folder) -> list[int]:
    directory = curve_policy_dir(folder)
    return sorted(int(p.stem.removeprefix("step")) for p in directory.glob("step*.pt"))


def kept_actor(folder, step):
    import torch

    state = torch.load(curve_policy_path(folder, step), weights_only=True)
    return [value.numpy() for value in state.values()]


def final_actor(folder):
    from distgprl.agents.sac import RegularisedSAC

    model = RegularisedSAC.load_saved(folder / "model.zip")
    return [value.numpy() for value in model.actor.state_dict().values()]


def row(success, collision, ret, step=0):
    return {"step": step, "success_rate": success, "collision_rate": collision, "mean_return": ret}


def test_best_point_is_the_highest_trained_curve_success_ties_to_the_later_point():
    """As pre-registered (FINDINGS "Protocol v6", rule 6; v8, rule 2): among the points after
    the first update, the highest curve success alone (collision rate and return do not
    break ties), and of equal ones the later point."""
    rows = [
        row(0.5, 0.0, 9.0, 0),
        row(0.8, 0.0, 99.0, 100),  # the same success with fewer collisions and more return...
        row(0.8, 0.4, 1.0, 200),
        row(0.8, 0.6, 0.0, 300),  # ...loses to the latest point of that success
        row(0.7, 0.0, 99.0, 400),
    ]
    assert best_curve_row(rows, LS, "run")["step"] == 300
    as_read = [{k: str(v) for k, v in r.items()} for r in rows]  # progress.csv gives strings
    assert best_curve_row(as_read, LS, "run")["step"] == "300"
    all_tie = [row(0.3, 0, 0, s) for s in (0, 100, 200, 300)]
    assert best_curve_row(all_tie, LS, "run")["step"] == 300


def test_step_zero_never_qualifies_even_with_the_highest_curve_success():
    """The untrained step-0 point, and every point up to learning_starts (no update yet), is
    never the best, however high its curve success; the selection says the untrained point
    was not beaten, and gives its curve success."""
    rows = [row(0.9, 0, 0, 0), row(0.95, 0, 0, LS), row(0.3, 0, 0, LS + 1), row(0.2, 0, 0, 200)]
    assert best_curve_row(rows, LS, "run")["step"] == LS + 1
    selection = policies.select_best(rows, LS, "run")
    assert (selection.step, selection.beats_untrained) == (LS + 1, False)
    assert selection.untrained_curve_success_rate == 0.9
    assert [policies.is_trained_point(r, LS) for r in rows] == [False, False, True, True]


def test_a_trained_point_beats_the_untrained_one_only_when_strictly_better():
    """``beats_untrained``: the best trained point's curve success is strictly above step
    0's; a tie does not beat it; a curve without a step-0 point leaves it unknown."""
    better = policies.select_best([row(0.4, 0, 0, 0), row(0.5, 0, 0, 100)], LS, "run")
    assert (better.beats_untrained, better.untrained_curve_success_rate) == (True, 0.4)
    tie = policies.select_best([row(0.5, 0, 0, 0), row(0.5, 0, 0, 100)], LS, "run")
    assert (tie.step, tie.beats_untrained) == (100, False)
    unknown = policies.select_best([row(0.5, 0, 0, 100)], LS, "run")
    assert (unknown.beats_untrained, unknown.untrained_curve_success_rate) == (None, None)
    assert better.record() == {
        "learning_starts": LS,
        "beats_untrained": True,
        "untrained_curve_success_rate": 0.4,
    }


def test_a_curve_without_a_trained_point_is_an_error_naming_the_run_folder():
    for rows in ([], [row(0.9, 0, 0, 0)], [row(0.9, 0, 0, 0), row(0.1, 0, 0, LS)]):
        with pytest.raises(
            UserInputError, match=r"^results/x/seed0: no learning-curve point after"
        ):
            best_curve_row(rows, LS, "results/x/seed0")


def test_a_point_is_kept_when_it_is_trained_and_ranks_at_least_as_high_as_every_earlier_one():
    """An untrained point (step <= learning_starts) is never kept; the first trained point
    is; a later one if it ranks at least as high as every earlier trained one: a tie keeps
    the later actor too, as `best_curve_row` selects the later of equal points, so the
    selected point always has its actor."""
    untrained, first = row(0.9, 0.0, 1.0, 0), row(0.5, 0.0, 1.0, 100)
    better, tie = row(0.6, 0.0, 0.0, 200), row(0.6, 0.9, -5.0, 300)
    assert not policies.beats_every_earlier([], untrained, LS)
    assert policies.beats_every_earlier([untrained], first, LS)  # step 0's 0.9 does not count
    assert policies.beats_every_earlier([untrained, first], better, LS)
    assert policies.beats_every_earlier([first, better], tie, LS)
    assert not policies.beats_every_earlier([better], row(0.5, 0, 0, 400), LS)
    curve = [untrained, row(0.5, 0, 0, 100), row(0.4, 0, 0, 200), row(0.6, 0.0, 0.0, 300)]
    curve += [row(0.6, 0.9, -5.0, 400), row(0.55, 0.0, 0.0, 500)]
    kept = [
        r["step"] for i, r in enumerate(curve) if policies.beats_every_earlier(curve[:i], r, LS)
    ]
    assert kept == [100, 300, 400] and best_curve_row(curve, LS, "run")["step"] == kept[-1]


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A 240-step dist-gprl run (curve points and checkpoints at 0/120/240 and 120/240)."""
    return train(tmp_path_factory.mktemp("run"), evaluate_after=False)


def test_a_curve_policy_is_kept_exactly_where_a_trained_point_beats_every_earlier_one(trained):
    _, progress = read_csv(trained / "progress.csv")
    expected, best = [], None
    for r in progress:
        if int(r["step"]) <= CI_LEARNING_STARTS:
            continue
        if best is None or curve_rank(r) >= best:
            expected.append(int(r["step"]))
            best = curve_rank(r)
    assert kept_steps(trained) == expected
    assert expected[0] == 120  # the first trained point; step 0 is never kept


@pytest.fixture(scope="module")
def ranked_by_step(tmp_path_factory):
    """A 240-step run (evaluated) whose curve ranking always improves (later is better)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(policies, "curve_rank", lambda r: (float(r["step"]),))
        root = tmp_path_factory.mktemp("ranked")
        folder = train(root)
    return root, folder


def test_every_kept_actor_is_the_actor_of_its_step(ranked_by_step):
    """With a ranking that always improves (step 0 ranking lowest), every trained point is
    kept and step 0 is not: the last one is the final model's actor, and it differs from
    the first trained one."""
    _, folder = ranked_by_step
    assert kept_steps(folder) == [120, 240]
    for kept, final in zip(kept_actor(folder, 240), final_actor(folder), strict=True):
        np.testing.assert_array_equal(kept, final)
    assert any(
        not np.array_equal(a, b)
        for a, b in zip(kept_actor(folder, 120), kept_actor(folder, 240), strict=True)
    )


def test_a_step_is_trained_exactly_when_sb3_has_taken_an_update_before_it(ranked_by_step):
    """The rule step > learning_starts against SB3's own count: the 240-step ci run's final
    model has taken 240 - learning_starts gradient steps (train_freq = gradient_steps = 1),
    so one update happened after step learning_starts + 1 was collected, none before."""
    from distgprl.agents.sac import RegularisedSAC

    _, folder = ranked_by_step
    model = RegularisedSAC.load_saved(folder / "model.zip")
    assert (model.learning_starts, model.train_freq.frequency) == (CI_LEARNING_STARTS, 1)
    assert model._n_updates == STEPS - CI_LEARNING_STARTS
    assert policies.is_trained_point({"step": CI_LEARNING_STARTS + 1}, model.learning_starts)
    assert not policies.is_trained_point({"step": CI_LEARNING_STARTS}, model.learning_starts)


def test_a_killed_and_resumed_run_keeps_the_same_curve_policies(
    tmp_path, kill_at_the_first_checkpoint, trained
):
    """Killed after its step-120 checkpoint; a curve policy of a later point that the resume
    discards (left by a kill between that point and the next checkpoint) is dropped, and the
    resumed run ends with the same kept policies, bit for bit, as the uninterrupted one."""
    kill_at_the_first_checkpoint(tmp_path)
    folder = run_dir(tmp_path, "ci", "dcp", "dist-gprl", 0)
    stale = curve_policy_path(folder, 180)
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
    summary = evaluate_run(
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
    """Ranking earliest first selects the earliest trained point (step 120; step 0 never
    qualifies): the evaluated policy is that actor (its returns differ from the final
    policy's), not the final one, and the summary records that it beat the untrained
    point (under this ranking step 0 ranks highest: it did not)."""
    monkeypatch.setattr(policies, "curve_rank", lambda r: (-float(r["step"]),))
    folder = train(tmp_path)
    loaded = {}
    original = policies.load_curve_policy

    def spy(folder_, model, step):
        original(folder_, model, step)
        loaded["step"] = step
        loaded["actor"] = [v.numpy().copy() for v in model.actor.state_dict().values()]

    monkeypatch.setattr(policies, "load_curve_policy", spy)
    summary = evaluate_run(
        "dcp", "dist-gprl", 0, "ci", root=tmp_path, show_progress=False, policy="best"
    )
    assert loaded["step"] == 120 and summary["policy_step"] == 120
    assert summary["beats_untrained"] is False and summary["learning_starts"] == 60
    _, progress = read_csv(folder / "progress.csv")
    assert summary["untrained_curve_success_rate"] == float(progress[0]["success_rate"])
    for a, b in zip(loaded["actor"], kept_actor(folder, 120), strict=True):
        np.testing.assert_array_equal(a, b)
    _, best_rows = read_csv(folder / "evaluation_best.csv")
    _, final_rows = read_csv(folder / "evaluation.csv")
    assert [r["return"] for r in best_rows] != [r["return"] for r in final_rows]


def test_training_evaluates_the_best_policy_beside_the_final_one(ranked_by_step):
    _, folder = ranked_by_step
    summary = read_json(folder / "summary_best.json")["summary"]
    assert summary["policy_step"] == 240 and summary["beats_untrained"] is True
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


@pytest.fixture(scope="module")
def untrained_only(tmp_path_factory):
    """A 60-step ci run (learning_starts 60): curve points at 0 and 60, neither trained;
    (root, folder, what training wrote to stderr)."""
    import contextlib
    import io

    root = tmp_path_factory.mktemp("untrained")
    with contextlib.redirect_stderr(io.StringIO()) as stderr:
        folder = train(root, steps=CI_LEARNING_STARTS)
    return root, folder, stderr.getvalue()


def test_training_without_a_trained_point_keeps_no_actor_and_skips_the_best_evaluation(
    untrained_only,
):
    _, folder, stderr = untrained_only
    _, progress = read_csv(folder / "progress.csv")
    assert [int(r["step"]) for r in progress] == [0, CI_LEARNING_STARTS]
    assert kept_steps(folder) == []
    assert (folder / "summary.json").exists() and not (folder / "summary_best.json").exists()
    assert "no learning-curve point after the first SAC update" in stderr
    assert "best-policy evaluation is skipped" in stderr


def test_a_best_policy_request_without_a_trained_point_exits_2_and_writes_nothing(
    untrained_only,
):
    """``evaluate --policy best``, shipping and loading the best policy of a run without a
    trained curve point: one line naming the run folder, exit 2, no file written."""
    import distgprl

    root, folder, _ = untrained_only
    before = sorted(p.name for p in folder.iterdir())
    arguments = ["evaluate", "--method", "dist-gprl", "--task", "dcp", "--preset", "ci"]
    result = CliRunner().invoke(app, [*arguments, "--root", str(root), "--policy", "best"])
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and str(folder) in lines[0], result.output
    assert "no learning-curve point after the first SAC update" in lines[0]
    for request in (
        lambda: policies.ship_best_policy(folder),
        lambda: distgprl.load_policy("dcp", "dist-gprl", 0, "ci", root=root, policy="best"),
    ):
        with pytest.raises(UserInputError, match=f"^{folder}: no learning-curve point after"):
            request()
    assert policies.ship_if_missing(folder) is None
    assert sorted(p.name for p in folder.iterdir()) == before


def test_a_best_point_without_its_kept_policy_is_a_clear_error(tmp_path):
    """Runs trained before curve policies were kept (or on another machine), that ship no
    best actor either, are refused, naming what is missing."""
    folder = train(tmp_path, steps=120, evaluate_after=False)
    for path in curve_policy_dir(folder).glob("*.pt"):
        path.unlink()
    with pytest.raises(UserInputError, match=r"neither the trained model with its kept curve"):
        evaluate_run("dcp", "dist-gprl", 0, "ci", root=tmp_path, show_progress=False, policy="best")


def test_bad_policy_choices_are_clear_errors(tmp_path):
    with pytest.raises(UserInputError, match="not trained"):
        evaluate_run("dcp", "demo", 0, "ci", root=tmp_path, policy="best")
    with pytest.raises(UserInputError, match="unknown policy 'worst'"):
        evaluate_run("dcp", "demo", 0, "ci", root=tmp_path, policy="worst")


def test_file_names_keep_the_final_policys_and_tag_the_best():
    assert evaluation_file_names() == ("evaluation.csv", "summary.json")
    assert evaluation_file_names(1000) == ("evaluation_n1000.csv", "summary_n1000.json")
    assert evaluation_file_names(None, "best") == (
        "evaluation_best.csv",
        "summary_best.json",
    )
    assert evaluation_file_names(1000, "best") == (
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
            "--json",
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

    from distgprl.schema import read_json

    monkeypatch.setenv("DISTGPRL_CHECKPOINT_ROOT", str(tmp_path / "ckpt"))
    folder = synthetic_run(tmp_path / "run", ((0, 0.1), (100, 0.6), (200, 0.6), (300, 0.2)))
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
    assert (record["beats_untrained"], record["untrained_curve_success_rate"]) == (True, 0.1)
    assert (record["learning_starts"], record["curve_success_rate"]) == (LS, 0.6)


def synthetic_run(folder, curve):
    """A run folder with a ``progress.csv`` of ``curve`` ((step, success) pairs) and a
    ``config.json`` giving learning_starts `LS`."""
    from distgprl.schema import PROGRESS_FIELDS, write_csv

    rows = []
    for step, success in curve:
        point = dict.fromkeys(PROGRESS_FIELDS, "")
        point.update(step=step, success_rate=success, collision_rate=0.0)
        rows.append(point)
    write_csv(folder / "progress.csv", rows, PROGRESS_FIELDS)
    config = {"run": {"config": {"sac": {"learning_starts": LS}}}}
    write_json(folder / "config.json", config, kind="config")
    return folder


def test_shipping_never_ships_step_zero_and_records_that_it_was_not_beaten(tmp_path, monkeypatch):
    """Step 0 has the highest curve success: the best trained point (200, the later of the
    tied trained ones) ships, its record saying no trained point beat the untrained one; a
    run with no trained point ships nothing and says which run."""
    monkeypatch.setenv("DISTGPRL_CHECKPOINT_ROOT", str(tmp_path / "ckpt"))
    folder = synthetic_run(tmp_path / "run", ((0, 0.9), (100, 0.6), (200, 0.6), (300, 0.2)))
    for step in (0, 100, 200, 300):
        policies.curve_policy_path(folder, step).parent.mkdir(parents=True, exist_ok=True)
        policies.curve_policy_path(folder, step).write_bytes(f"actor {step}".encode())
    assert policies.ship_best_policy(folder).read_bytes() == b"actor 200"
    record = read_json(folder / policies.SHIPPED_POLICY_RECORD)
    assert (record["step"], record["beats_untrained"]) == (200, False)
    assert record["untrained_curve_success_rate"] == 0.9
    bare = synthetic_run(tmp_path / "bare", ((0, 0.9), (LS, 0.1)))
    policies.curve_policy_path(bare, 0).parent.mkdir(parents=True, exist_ok=True)
    policies.curve_policy_path(bare, 0).write_bytes(b"actor 0")
    with pytest.raises(UserInputError, match=f"^{bare}: no learning-curve point after"):
        policies.ship_best_policy(bare)
    assert policies.ship_if_missing(bare) is None
    assert not (bare / policies.SHIPPED_POLICY).exists()
    assert not (bare / policies.SHIPPED_POLICY_RECORD).exists()
