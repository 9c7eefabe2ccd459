"""train / evaluate runs at reduced size: every method, determinism, resume, bad input."""

from __future__ import annotations

import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest

from distgprl.errors import UserInputError
from distgprl.experiments import checkpoints, training
from distgprl.experiments.checkpoints import checkpoint_dir, has_checkpoint, save_checkpoint
from distgprl.experiments.evaluation import evaluate_run
from distgprl.experiments.run_control import TrainingInterrupted
from distgprl.experiments.training import train_run
from distgprl.identity import resolve_run
from distgprl.limits import SafetyLimits
from distgprl.methods import METHODS
from distgprl.schema import read_csv, read_json, run_dir, write_json

STEPS = 120  # the `ci` preset shortened further; still past learning_starts


def train(tmp_path, method, task="dcp", seed=0, steps=STEPS, **kwargs):
    return train_run(
        task,
        method,
        seed,
        preset="ci",
        steps=steps,
        root=tmp_path,
        show_progress=False,
        **kwargs,
    )


def _load_model(path):
    """A saved `RegularisedSAC` (its regulariser and schedule are rebuilt, never pickled)."""
    from distgprl.agents.sac import RegularisedSAC

    return RegularisedSAC.load_saved(path)


@pytest.mark.parametrize(
    "method", [name for name, spec in METHODS.items() if spec.trainable]
)  # a method added to the registry is covered without touching this test
def test_every_method_trains_and_evaluates(tmp_path, method):
    folder = train(tmp_path, method)
    for name in (
        "config.json",
        "progress.csv",
        "evaluation.csv",
        "summary.json",
        "evaluation_best.csv",  # Algorithm 1's best policy, evaluated beside the final one
        "summary_best.json",
        "done.json",
        "model.zip",
    ):
        assert (folder / name).exists(), name
    summary = read_json(folder / "summary.json")["summary"]
    assert 0.0 <= summary["success_rate"] <= 1.0
    assert 0.0 <= summary["collision_rate"] <= 1.0
    _, progress = read_csv(folder / "progress.csv")
    assert [int(r["step"]) for r in progress] == [0, 120]
    _, rows = read_csv(folder / "evaluation.csv")
    assert len(rows) == 6
    if method in ("dist-gprl", "gprl-h", "dist-gprl-global", "dist-gprl-nocov"):
        assert progress[-1]["l_hap"] != ""
    if method == "gprl":
        assert float(progress[-1]["ent_coef"]) < 0.2


def test_same_seed_gives_identical_progress(tmp_path):
    a = train(tmp_path / "a", "dist-gprl", evaluate_after=False)
    b = train(tmp_path / "b", "dist-gprl", evaluate_after=False)
    _, rows_a = read_csv(a / "progress.csv")
    _, rows_b = read_csv(b / "progress.csv")
    for ra, rb in zip(rows_a, rows_b, strict=True):
        for key in ("success_rate", "collision_rate", "mean_return", "l_sim", "l_hap"):
            assert ra[key] == rb[key], key


def test_resume_after_a_kill_reaches_the_same_step_count_with_the_buffer(tmp_path, monkeypatch):
    original = training.save_checkpoint
    calls = {"n": 0}

    def save_then_die(folder, model, env, extra):
        original(folder, model, env, extra)
        calls["n"] += 1
        if calls["n"] == 1:
            raise KeyboardInterrupt  # killed right after the first checkpoint

    monkeypatch.setattr(training, "save_checkpoint", save_then_die)
    with pytest.raises(KeyboardInterrupt):
        train(tmp_path, "dist-gprl", steps=240, evaluate_after=False)
    folder = run_dir(tmp_path, "ci", "dcp", "dist-gprl", 0)
    assert not (folder / "done.json").exists()
    with pytest.raises(UserInputError, match="pass --resume"):
        train(tmp_path, "dist-gprl", steps=240, evaluate_after=False)
    monkeypatch.setattr(training, "save_checkpoint", original)
    train(tmp_path, "dist-gprl", steps=240, evaluate_after=False, resume=True)
    done = read_json(folder / "done.json")
    assert done["steps"] == 240
    # process CPU seconds of training, carried over the resume by the checkpoint
    state = pickle.loads((checkpoint_dir(folder) / "state.pkl").read_bytes())
    checkpoint_cpu = state["cpu_time_s"]
    assert 0.0 < checkpoint_cpu <= done["train_cpu_time_s"]
    assert done["cpu_s_per_step"] == pytest.approx(done["train_cpu_time_s"] / 240)
    model = _load_model(checkpoint_dir(folder) / "model.zip")
    model.load_replay_buffer(checkpoint_dir(folder) / "replay_buffer.pkl")
    assert model.num_timesteps == 240
    assert model.replay_buffer.size() == 240
    _, progress = read_csv(folder / "progress.csv")
    assert [int(r["step"]) for r in progress] == [0, 120, 240]


def test_a_resume_removes_the_partial_write_a_killed_process_left(tmp_path, capsys, monkeypatch):
    """A process killed between creating an atomic write's temporary file and renaming it
    (kill -9, a frozen node let go) leaves ``.<name>.<random>.tmp`` in the run folder; the
    next process that takes the run's lock removes it with one line, and the run finishes
    with nothing left behind."""
    original = training.save_checkpoint

    def save_then_die(folder, model, env, extra):
        original(folder, model, env, extra)
        raise KeyboardInterrupt  # killed right after the first checkpoint

    monkeypatch.setattr(training, "save_checkpoint", save_then_die)
    with pytest.raises(KeyboardInterrupt):
        train(tmp_path, "dist-gprl", steps=240, evaluate_after=False)
    monkeypatch.setattr(training, "save_checkpoint", original)
    folder = run_dir(tmp_path, "ci", "dcp", "dist-gprl", 0)
    leftover = folder / ".progress.csv.meta.json.wsaoftax.tmp"
    leftover.write_text("a write that never finished")
    capsys.readouterr()
    train(tmp_path, "dist-gprl", steps=240, evaluate_after=False, resume=True)
    assert not leftover.exists()
    assert f"removed {leftover.name}" in capsys.readouterr().err
    assert read_json(folder / "done.json")["steps"] == 240
    assert not list(folder.glob(".*.tmp"))


def _actor_parameters(folder):
    model = _load_model(folder / "model.zip")
    return [p.detach().numpy().copy() for p in model.actor.parameters()]


def test_resume_without_its_checkpoint_restarts_visibly_and_on_record(
    tmp_path, kill_at_the_first_checkpoint, capsys
):
    """A killed run whose checkpoint is gone (checkpoints stay on the machine that trained)
    restarts from step 0 with a warning naming the lost step, and done.json records it."""
    kill_at_the_first_checkpoint(tmp_path)
    folder = run_dir(tmp_path, "ci", "dcp", "dist-gprl", 0)
    shutil.rmtree(checkpoint_dir(folder))
    capsys.readouterr()
    train(tmp_path, "dist-gprl", steps=240, evaluate_after=False, resume=True)
    err = capsys.readouterr().err
    [resume] = read_json(folder / "done.json")["resumes"]
    lost = resume["restarted_after_step"]  # the killed run's first checkpoint (see below)
    assert 120 <= lost < 123 and f"reached step {lost} and restarts from step 0" in err
    assert resume == {"step": 0, "exact": False, "restarted_after_step": lost}
    _, progress = read_csv(folder / "progress.csv")
    assert [int(r["step"]) for r in progress] == [0, 120, 240]


def test_a_killed_and_resumed_run_equals_the_uninterrupted_run(
    tmp_path, kill_at_the_first_checkpoint
):
    """Same seed, same result, however often the run was killed and resumed."""
    whole = train(tmp_path / "whole", "dist-gprl", steps=240, evaluate_after=False)
    kill_at_the_first_checkpoint(tmp_path / "killed")
    resumed = train(tmp_path / "killed", "dist-gprl", steps=240, evaluate_after=False, resume=True)
    _, rows_whole = read_csv(whole / "progress.csv")
    _, rows_resumed = read_csv(resumed / "progress.csv")
    assert [r["step"] for r in rows_resumed] == ["0", "120", "240"]
    for a, b in zip(rows_whole, rows_resumed, strict=True):
        a.pop("wall_time_s"), b.pop("wall_time_s")
        assert a == b
    for a, b in zip(_actor_parameters(whole), _actor_parameters(resumed), strict=True):
        np.testing.assert_array_equal(a, b)
    assert read_json(whole / "done.json")["resumes"] == []
    # the first checkpoint: at step 120, or (v5: a collision ends an episode early) at the
    # end of the episode that step 120 falls in
    [resume] = read_json(resumed / "done.json")["resumes"]
    assert resume["exact"] and 120 <= resume["step"] < 120 + 3


@pytest.fixture(scope="module")
def uninterrupted_run(tmp_path_factory):
    """A 240-step dist-gprl run that was never killed (checkpoints at 120 and 240)."""
    return train(tmp_path_factory.mktemp("whole"), "dist-gprl", steps=240, evaluate_after=False)


@pytest.mark.parametrize("kill_point", ["writing the buffer", "moving the pieces into place"])
def test_a_kill_inside_a_checkpoint_write_resumes_exactly(
    tmp_path, monkeypatch, uninterrupted_run, kill_point
):
    """Killed while the step-240 checkpoint is half written: the resume uses the step-120
    checkpoint (roll back) or the complete step-240 one (roll forward), never a model of one
    step with the buffer and generators of another, and ends equal to the uninterrupted run."""
    from distgprl.agents.sac import RegularisedSAC

    calls = {"save": 0}
    if kill_point == "writing the buffer":
        original_save = RegularisedSAC.save_replay_buffer

        def die_in_second_save(self, path):
            calls["save"] += 1
            if calls["save"] == 2:
                original_save(self, path)  # a complete file under its temporary name...
                raise KeyboardInterrupt  # ...but the kill comes before the commit marker
            original_save(self, path)

        monkeypatch.setattr(RegularisedSAC, "save_replay_buffer", die_in_second_save)
        resumed_at = 120
    else:
        original_install = checkpoints.install_checkpoint

        def die_after_moving_the_model(paths):
            calls["save"] += 1
            if calls["save"] == 2:  # as `install_checkpoint`: rotate, then move the pieces
                checkpoints.rotate_generations(paths)
                (paths["dir"] / ".model.tmp.zip").replace(paths["model"])
                raise KeyboardInterrupt
            original_install(paths)

        monkeypatch.setattr(checkpoints, "install_checkpoint", die_after_moving_the_model)
        resumed_at = 240
    with pytest.raises(KeyboardInterrupt):
        train(tmp_path, "dist-gprl", steps=240, evaluate_after=False)
    monkeypatch.undo()
    folder = run_dir(tmp_path, "ci", "dcp", "dist-gprl", 0)
    resumed = train(tmp_path, "dist-gprl", steps=240, evaluate_after=False, resume=True)
    [resume] = read_json(folder / "done.json")["resumes"]
    assert resume["exact"] and resumed_at <= resume["step"] < resumed_at + 3  # see above
    assert sorted(p.name for p in checkpoint_dir(folder).iterdir()) == [
        "curve_policies",  # the best-so-far learning-curve actors (`--policy best`)
        "manifest.json",  # size and SHA-256 of the three pieces
        "model.zip",
        "previous",  # the step-120 generation, what a damaged step-240 one falls back to
        "replay_buffer.pkl",
        "state.pkl",
    ]
    previous = checkpoints.checkpoint_paths(folder)["previous"]
    assert pickle.loads((previous / "state.pkl").read_bytes())["num_timesteps"] < 240
    assert sorted(p.name for p in previous.iterdir()) == [
        "manifest.json",
        "model.zip",
        "replay_buffer.pkl",
        "state.pkl",
    ]
    model = _load_model(checkpoint_dir(folder) / "model.zip")
    model.load_replay_buffer(checkpoint_dir(folder) / "replay_buffer.pkl")
    assert model.replay_buffer.size() == 240
    for a, b in zip(_actor_parameters(uninterrupted_run), _actor_parameters(resumed), strict=True):
        np.testing.assert_array_equal(a, b)


def test_checkpoints_of_two_results_roots_never_share_a_folder(tmp_path, monkeypatch):
    first = run_dir(tmp_path / "results", "paper", "dbm", "dist-gprl", 1)
    second = run_dir(tmp_path / "exploration" / "longer", "paper", "dbm", "dist-gprl", 1)
    monkeypatch.delenv("DISTGPRL_CHECKPOINT_ROOT", raising=False)
    assert checkpoint_dir(first) == first / "checkpoints"
    cache = tmp_path / "cache"
    monkeypatch.setenv("DISTGPRL_CHECKPOINT_ROOT", str(cache))
    paths = checkpoint_dir(first), checkpoint_dir(second)
    assert paths[0] != paths[1]
    for folder, path in zip((first, second), paths, strict=True):
        assert path.is_relative_to(cache)
        assert path.parent.parts[-4:] == folder.parts[-4:]  # preset/task/method/seed readable


def test_evaluate_demo_reference_writes_summary(tmp_path):
    summary = evaluate_run("dcp", "demo", 0, "ci", root=tmp_path, show_progress=False)
    episodes = resolve_run("dcp", "demo", 0, "ci").config.run.eval_episodes
    assert summary["episodes"] == episodes
    folder = run_dir(tmp_path, "ci", "dcp", "demo", 0)
    meta, rows = read_csv(folder / "evaluation.csv")
    assert meta["method"] == "demo" and len(rows) == episodes
    assert np.isfinite(float(rows[0]["min_clearance"]))
    peaks = np.array([float(r["peak_joint_speed"]) for r in rows])
    assert np.all(peaks > 0)
    assert summary["peak_joint_speed_p95"] == pytest.approx(np.percentile(peaks, 95))
    limit = SafetyLimits().max_joint_speed
    assert summary["joint_speed_over_limit_rate"] == pytest.approx(np.mean(peaks > limit))


def test_a_fresh_evaluation_csv_reads_with_plain_pandas_one_row_per_episode(tmp_path):
    """``pandas.read_csv`` with its defaults: the documented EVALUATION_FIELDS as columns,
    one row per evaluation episode, the values `read_csv` reads."""
    pandas = pytest.importorskip("pandas")
    from distgprl.schema import EVALUATION_FIELDS

    evaluate_run("dcp", "demo", 0, "ci", root=tmp_path, show_progress=False)
    folder = run_dir(tmp_path, "ci", "dcp", "demo", 0)
    frame = pandas.read_csv(folder / "evaluation.csv")
    episodes = resolve_run("dcp", "demo", 0, "ci").config.run.eval_episodes
    assert list(frame.columns) == list(EVALUATION_FIELDS)
    assert len(frame) == episodes
    _, rows = read_csv(folder / "evaluation.csv")
    np.testing.assert_allclose(frame["min_clearance"], [float(r["min_clearance"]) for r in rows])
    assert read_json(folder / "evaluation.csv.meta.json")["meta"]["method"] == "demo"


def test_a_supplementary_evaluation_extends_the_presets_tcs_beside_its_files(tmp_path):
    """``--episodes N`` other than the preset's writes ``evaluation_n<N>.csv`` whose first
    TCs are the preset's (same outcomes), and leaves the preset's evaluation and the
    config untouched."""
    evaluate_run("dcp", "demo", 0, "ci", root=tmp_path, show_progress=False)
    folder = run_dir(tmp_path, "ci", "dcp", "demo", 0)
    preset_text = (folder / "evaluation.csv").read_text()
    config_text = (folder / "config.json").read_text()
    _, preset_rows = read_csv(folder / "evaluation.csv")
    n = len(preset_rows) + 2
    summary = evaluate_run("dcp", "demo", 0, "ci", episodes=n, root=tmp_path, show_progress=False)
    assert summary["episodes"] == n
    assert (folder / "evaluation.csv").read_text() == preset_text
    assert (folder / "config.json").read_text() == config_text
    assert read_json(folder / "summary.json")["summary"]["episodes"] == len(preset_rows)
    _, rows = read_csv(folder / f"evaluation_n{n}.csv")
    assert read_json(folder / f"summary_n{n}.json")["summary"]["episodes"] == n
    skip = ("adaptation_ms", "policy_ms")  # wall-clock times, the only fields that may differ
    for extended, original in zip(rows, preset_rows, strict=False):
        assert {k: v for k, v in extended.items() if not k.startswith(skip)} == {
            k: v for k, v in original.items() if not k.startswith(skip)
        }


def test_missing_model_and_bad_names_are_clear_errors(tmp_path):
    with pytest.raises(UserInputError, match="no trained model"):
        evaluate_run("dcp", "dist-gprl", 0, "ci", root=tmp_path, show_progress=False)
    with pytest.raises(UserInputError, match="valid methods"):
        evaluate_run("dcp", "nope", 0, "ci", root=tmp_path)
    with pytest.raises(UserInputError, match="valid tasks"):
        evaluate_run("nope", "demo", 0, "ci", root=tmp_path)
    with pytest.raises(UserInputError, match="does not train"):
        train_run("dcp", "demo", 0, "ci", root=tmp_path)


def _model_folder(root, config_hash):
    """A dist-gprl run folder with a junk model and a config.json recording ``config_hash``."""
    folder = run_dir(root, "ci", "dcp", "dist-gprl", 0)
    folder.mkdir(parents=True)
    (folder / "model.zip").write_bytes(b"junk")
    write_json(folder / "config.json", {"config_hash": config_hash}, config_hash=config_hash)
    return folder


def test_incompatible_model_file_is_a_clear_error(tmp_path):
    _model_folder(tmp_path, resolve_run("dcp", "dist-gprl", 0, "ci").hash)
    with pytest.raises(UserInputError, match="cannot load model"):
        evaluate_run("dcp", "dist-gprl", 0, "ci", root=tmp_path, show_progress=False)


def test_a_model_of_another_configuration_is_not_evaluated_under_the_current_one(tmp_path):
    """A model trained before the configuration changed (its config.json records another
    hash) is refused: evaluating it would stamp the current hash on an old model."""
    _model_folder(tmp_path, "0123456789abcdef")
    with pytest.raises(UserInputError, match="trained with configuration 0123456789abcdef"):
        evaluate_run("dcp", "dist-gprl", 0, "ci", root=tmp_path, show_progress=False)


def test_the_evaluation_and_curve_seeds_are_reserved():
    """No run may use the seeds that draw the evaluation or learning-curve TCs (training
    on them would train on the test set)."""
    from distgprl.schema import EVALUATION_SEED, TRAINING_CURVE_SEED

    for seed in (EVALUATION_SEED, TRAINING_CURVE_SEED):
        with pytest.raises(UserInputError, match="reserved"):
            resolve_run("dcp", "dist-gprl", seed, "ci")
    assert resolve_run("dcp", "dist-gprl", 3, "ci").seed == 3


def test_checkpoint_pieces_reach_the_disk_before_the_commit_marker(tmp_path, monkeypatch):
    """The model and replay buffer SB3 writes are fsynced before the commit marker is
    written, so after a power loss the marker never commits a piece still in the page cache."""
    import os

    import gymnasium

    class Model:
        num_timesteps, _episode_num = 7, 2
        action_space = gymnasium.spaces.Box(-1.0, 1.0, (2,))

        def save(self, path):
            Path(path).write_bytes(b"model")

        def save_replay_buffer(self, path):
            Path(path).write_bytes(b"buffer")

    class Env:
        tc = None
        tc_generator_state = np.random.default_rng(0).bit_generator.state

    synced, real_fsync = [], os.fsync

    def fsync(descriptor):
        synced.append(Path(os.readlink(f"/proc/self/fd/{descriptor}")).name)
        real_fsync(descriptor)

    monkeypatch.setattr(os, "fsync", fsync)
    save_checkpoint(tmp_path, Model(), Env(), {})
    commit = next(i for i, name in enumerate(synced) if name.startswith(".commit.json."))
    assert {".model.tmp.zip", ".buffer.tmp.pkl"} <= set(synced[:commit])
    assert has_checkpoint(tmp_path)


@pytest.mark.parametrize("seed", [-1, 2**32, 1.5, True])
def test_a_seed_outside_0_to_2_32_is_refused_before_anything_is_written(tmp_path, seed):
    """`resolve_run` (where train, evaluate and the sweep start) refuses a seed NumPy and
    torch would reject mid-start, and `train_run` / `evaluate_run` create no folder."""
    with pytest.raises(UserInputError, match="must be an integer from 0 to 2\\*\\*32 - 1"):
        resolve_run("dcp", "dist-gprl", seed, "ci")
    with pytest.raises(UserInputError, match="seed"):
        train_run("dcp", "dist-gprl", seed, "ci", root=tmp_path, show_progress=False)
    with pytest.raises(UserInputError, match="seed"):
        evaluate_run("dcp", "demo", seed, "ci", root=tmp_path, show_progress=False)
    assert list(tmp_path.iterdir()) == []
    assert resolve_run("dcp", "dist-gprl", 2**32 - 1, "ci").seed == 2**32 - 1


@pytest.mark.parametrize("steps", [0, -3, 4, 121])
def test_steps_must_be_a_positive_multiple_of_the_episode_length(tmp_path, steps):
    """Total steps of 0, a negative multiple or a non-multiple of the episode (3 RL steps)
    are refused by `resolve_run`, before `train_run` writes anything."""
    with pytest.raises(UserInputError, match="positive multiple of the episode length"):
        resolve_run("dcp", "dist-gprl", 0, "ci", steps)
    with pytest.raises(UserInputError, match="positive multiple"):
        train(tmp_path, "dist-gprl", steps=steps)
    assert list(tmp_path.iterdir()) == []
    assert resolve_run("dcp", "dist-gprl", 0, "ci", 3).config.run.total_steps == 3


def test_a_bad_preset_is_refused_before_anything_is_written(tmp_path):
    with pytest.raises(UserInputError, match="unknown preset 'nope'"):
        train_run("dcp", "dist-gprl", 0, "nope", root=tmp_path, show_progress=False)
    assert list(tmp_path.iterdir()) == []


def test_a_start_that_fails_before_training_leaves_nothing_behind(tmp_path, monkeypatch):
    """An error while the run is set up (after config.json and .lock were written) removes
    what this start created: the next try is not told "run exists". Folders that existed
    before (here the task folder of another run) stay."""
    other = run_dir(tmp_path, "ci", "dcp", "gprl-d", 0)
    other.mkdir(parents=True)

    def broken_env(run):
        raise RuntimeError("simulated start-up failure")

    monkeypatch.setattr(training, "make_env", broken_env)
    with pytest.raises(RuntimeError, match="simulated start-up failure"):
        train(tmp_path, "dist-gprl")
    assert not run_dir(tmp_path, "ci", "dcp", "dist-gprl", 0).parent.exists()
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*")) == [
        "ci",
        "ci/dcp",
        "ci/dcp/gprl-d",
        "ci/dcp/gprl-d/seed0",
    ]


def test_a_failed_resume_keeps_the_runs_files(tmp_path, monkeypatch):
    """A start-up failure of a resumed run removes nothing it did not create: the run's
    config.json (from the earlier start) stays."""
    folder = run_dir(tmp_path, "ci", "dcp", "dist-gprl", 0)
    folder.mkdir(parents=True)
    run = resolve_run("dcp", "dist-gprl", 0, "ci", STEPS)
    write_json(folder / "config.json", {"run": run.to_dict(), "config_hash": run.hash})

    def broken_env(run):
        raise RuntimeError("simulated start-up failure")

    monkeypatch.setattr(training, "make_env", broken_env)
    with pytest.raises(RuntimeError, match="simulated"):
        train(tmp_path, "dist-gprl", resume=True)
    assert (folder / "config.json").exists()


def _event_scalars(folder: Path) -> dict[str, list[tuple[int, float]]]:
    """Every scalar tag of a run's ``tb/`` event files: ``tag -> [(step, value), ...]``."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(folder / "tb"))
    events.Reload()
    return {
        tag: [(event.step, event.value) for event in events.Scalars(tag)]
        for tag in events.Tags()["scalars"]
    }


def test_each_run_writes_tensorboard_events_without_changing_its_training(tmp_path, monkeypatch):
    """A run's ``tb/`` holds the losses, alpha, regulariser terms, gradient norms, training
    episodes and curve points, and training with it is bit-identical to training without."""
    pytest.importorskip("tensorboard")
    from distgprl.agents import sac

    logged = train(tmp_path / "logged", "dist-gprl", evaluate_after=False)
    scalars = _event_scalars(logged)
    for tag in (
        "train/actor_loss",
        "train/critic_loss",
        "train/ent_coef",
        "train/l_sim",
        "train/l_hap",
        "rollout/episode_return",
        "rollout/episode_success",
        "rollout/episode_collision",
        "curve/success_rate",
        "curve/collision_rate",
        "curve/mean_return",
        "curve/grad_q",
        "curve/grad_sim",
        "curve/grad_hap",
    ):
        assert scalars.get(tag), tag
    _, progress = read_csv(logged / "progress.csv")
    assert [step for step, _ in scalars["curve/success_rate"]] == [0, 120]
    assert scalars["curve/success_rate"][-1][1] == pytest.approx(
        float(progress[-1]["success_rate"])
    )
    assert len(scalars["rollout/episode_return"]) == int(progress[-1]["episodes"])

    monkeypatch.setattr(sac, "training_logger", lambda tb_dir, start_step=0: sac.Logger(None, []))
    silent = train(tmp_path / "silent", "dist-gprl", evaluate_after=False)
    assert not (silent / "tb").exists()
    _, silent_progress = read_csv(silent / "progress.csv")
    for a, b in zip(progress, silent_progress, strict=True):
        a.pop("wall_time_s"), b.pop("wall_time_s")
        assert a == b
    for a, b in zip(_actor_parameters(logged), _actor_parameters(silent), strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_resumed_runs_events_purge_what_the_killed_process_logged_after_its_checkpoint(
    tmp_path, monkeypatch
):
    """Killed at its second checkpoint (after logging steps 120..240) and resumed from the
    first: each curve point and each training episode appears once in the event files."""
    pytest.importorskip("tensorboard")
    original = training.save_checkpoint
    calls = []

    def die_at_the_second(folder, model, env, extra):
        calls.append(model.num_timesteps)
        if len(calls) == 2:
            raise KeyboardInterrupt
        original(folder, model, env, extra)

    monkeypatch.setattr(training, "save_checkpoint", die_at_the_second)
    with pytest.raises(TrainingInterrupted):
        train(tmp_path, "dist-gprl", steps=240, evaluate_after=False)
    monkeypatch.setattr(training, "save_checkpoint", original)
    folder = train(tmp_path, "dist-gprl", steps=240, evaluate_after=False, resume=True)
    scalars = _event_scalars(folder)
    assert [step for step, _ in scalars["curve/success_rate"]] == [0, 120, 240]
    episode_steps = [step for step, _ in scalars["rollout/episode_return"]]
    assert episode_steps == sorted(set(episode_steps))
    _, progress = read_csv(folder / "progress.csv")
    assert len(episode_steps) == int(progress[-1]["episodes"])


def test_without_tensorboard_training_says_once_that_no_event_file_is_written(
    tmp_path, monkeypatch, capsys
):
    """The optional package missing: training works, one note on stderr, no ``tb/``."""
    from distgprl.agents import sac

    monkeypatch.setattr(sac, "tensorboard_available", lambda: False)
    monkeypatch.setattr(sac, "_TENSORBOARD_NOTE_SHOWN", False)
    capsys.readouterr()
    first = train(tmp_path / "a", "gprl", evaluate_after=False)
    second = train(tmp_path / "b", "gprl", evaluate_after=False)
    assert (first / "model.zip").exists() and (second / "model.zip").exists()
    assert not (first / "tb").exists()
    assert capsys.readouterr().err.count("no TensorBoard event file is written") == 1
