"""ProMP-RRL residual environment."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.adaptation.trajectories import variance_gate
from distgprl.envs.windowed_residual_env import (
    ResidualEnv,
    expert_demonstration_set,
    load_task_promp,
    one_demonstration_set,
)
from distgprl.sim.tasks import get_task
from distgprl.sim.tasks.base import condition_by_translation
from distgprl.skill.demos import load_demonstration


@pytest.fixture(scope="module")
def env():
    env = ResidualEnv("dcp")
    yield env
    env.close()


def test_zero_action_executes_the_nominal_trajectory(env):
    tc = env.spec_task.evaluation_tcs(2)[1]
    env.reset(options={"tc": tc})
    for step in range(3):
        segment = env.window_plan.segments[step]
        tau, lo, hi = segment.tau, segment.lo, segment.hi
        poses = env.segment_poses(step)
        # Only the first segment may blend out the robot-vs-ProMP start mismatch; past the
        # blend (and in every later segment) the nominal is executed exactly.
        past_blend = tau >= lo + env.config.blend_fraction * (hi - lo)
        np.testing.assert_allclose(poses[past_blend], env.nominal(tau[past_blend]), atol=1e-9)
        if step > 0:
            np.testing.assert_allclose(poses, env.nominal(tau), atol=1e-9)
        env.step(np.zeros(env.action_space.shape))


def test_nominal_starts_at_the_robot_and_engages_the_moved_object(env):
    """Object-centric: at the interaction time the nominal moves with the object offset."""
    tc_a, tc_b = env.spec_task.evaluation_tcs(2)
    interaction = np.array([env.spec_task.interaction_time])
    env.reset(options={"tc": tc_a})
    engage_a = env.nominal(interaction)[0, :2]
    np.testing.assert_allclose(
        env.nominal(np.zeros(1))[0, :3], env.window_plan.start_pose[:3], atol=2e-3
    )
    env.reset(options={"tc": tc_b})
    engage_b = env.nominal(interaction)[0, :2]
    shift = np.subtract(tc_b.object_offset, tc_a.object_offset)
    np.testing.assert_allclose(engage_b - engage_a, shift, atol=0.03)


def test_residual_action_changes_only_the_window_weights(env):
    env.reset(options={"tc": env.spec_task.nominal_tc})
    env.step(np.full(env.action_space.shape, 0.5))
    window = env.layout.indices[0]
    assert np.all(env.gamma[window] != 0)
    assert np.all(np.delete(env.gamma, window, axis=0) == 0)
    assert env.observation_space["state"].shape == (42,)


def test_promp_rrl_gets_only_the_one_demonstration_conditioned_on_training_tcs():
    """v5, equal information: every copy in ProMP-RRL's demonstration set is the shipped
    demonstration moved by its TC's object offset (the conditioning rule), nothing else."""
    spec = get_task("dcp")
    demo = load_demonstration(spec.demo_path)
    demos, offsets = one_demonstration_set("dcp")
    assert len(demos) == 20 and offsets.shape == (20, 3)
    assert np.ptp(offsets[:, :2], axis=0).min() > 0.1  # the TCs vary
    for (times, poses), offset in zip(demos, offsets, strict=True):
        np.testing.assert_array_equal(times, demo.times)
        expected = condition_by_translation(
            demo.times,
            demo.poses,
            offset[:2],
            spec.interaction_time,
            goal_fixed_in_world=spec.goal_fixed_in_world,
        )
        np.testing.assert_array_equal(poses, expected)


def test_one_demonstration_promp_varies_where_the_conditioning_weight_is_not_one():
    """In the object frame the conditioned copies coincide where the TC conditioning moves
    the skill whole with the object (weight 1) and differ elsewhere: on DBM (goal moves with
    the bar) everywhere after the interaction; on DCP (goal fixed, environment v6) only at
    the interaction, the push returning to the world-fixed goal after it. Before the
    interaction both differ (> 1 cm at the start). The variance gate follows: it lets the
    residual act fully where the copies coincide and not at the start."""
    for task, late_coincides in (("dbm", True), ("dcp", False)):
        promp = load_task_promp(task, "one")
        interaction = get_task(task).interaction_time
        late = np.linspace(interaction + 0.05, 1.0, 10)
        late_std = promp.trajectory_std(late)[:, :3].max()
        assert (late_std < 2e-3) == late_coincides, (task, late_std)
        assert promp.trajectory_std(np.zeros(1))[0, :2].min() > 0.01
        gate = variance_gate(promp, np.linspace(0.0, 1.0, 15))
        assert gate.min() == pytest.approx(0.0)
        assert np.all((gate >= 0.0) & (gate <= 1.0))
        at = variance_gate(promp, np.r_[np.linspace(0.0, 1.0, 15), interaction])[-1]
        assert at > 0.9, (task, at)


def test_residual_basis_is_normalised_so_the_total_range_is_the_gp_methods():
    """v5: the residual basis sums to the gate at every time (a partition of unity before
    gating), so saturating every weight by the action scale moves a pose by at most the
    scale — the GP methods' total range — never the ~2.5x of v4's unnormalised basis."""
    env = ResidualEnv("dcp")
    tau = np.linspace(0.0, 1.0, 200)
    basis = env.residual_basis(tau)
    gate = variance_gate(env.promp, env.skill.via_times)
    assert basis.min() >= 0.0 and basis.sum(axis=1).max() <= 1.0 + 1e-12
    ungated = basis / np.where(gate > 0, gate, 1.0)[None, :]
    full = gate > 0
    np.testing.assert_allclose(ungated[:, full].sum(axis=1)[tau > 0.9], 1.0, atol=1e-6)
    scale = env.layout.scale[0]
    weights = np.full((env.skill.n_via_points, 6), scale)
    assert np.abs(basis @ weights).max() <= scale + 1e-12
    env.close()


def test_expert_variant_and_nominal_reference():
    """``promp-rrl-expert`` fits the 20 shipped expert demonstrations; environment v6's
    ``promp-nominal`` reference is the residual-RL env's nominal (residual-control, not this
    windowed env, which refuses it)."""
    expert = ResidualEnv("dcp", method="promp-rrl-expert")
    assert expert.promp.demonstration_count == 20
    assert not np.allclose(expert.promp.weight_mean, load_task_promp("dcp", "one").weight_mean)
    expert.close()
    with pytest.raises(ValueError, match="not a residual method"):
        ResidualEnv("dcp", method="promp-nominal")


# -- the 20 expert demonstrations of Table I's ProMP-RRL (Protocol v8 rule 3) -------------------


def _tc_array(tcs) -> np.ndarray:
    """TCs -> (n, 4): object offset (dx, dy) and obstacle offset (dx, dy), m."""
    return np.array([[*tc.object_offset, *tc.obstacle_offset] for tc in tcs], dtype=float)


@pytest.mark.parametrize("task", ["dcp", "dbm"])
def test_expert_set_is_twenty_demonstrations_on_tcs_no_evaluation_or_curve_draws(task):
    """The shipped set loads (20 demonstrations, each executed successfully and collision-free
    on its own TC by `expert_demonstration_set`), and its TCs are none of the evaluation or
    learning-curve TCs any shipped preset draws: no demonstration TC equals one of them within
    1e-9 m on any of the four offsets."""
    from distgprl.config import load_config, shipped_presets
    from distgprl.sim.tasks.base import TaskConfig
    from distgprl.skill.demos import load_demonstration_set

    demos, offsets = expert_demonstration_set(task)
    assert len(demos) == 20 and offsets.shape == (20, 3) and np.all(offsets[:, 2] == 0.0)
    entries = load_demonstration_set(get_task(task).varied_demo_dir, 20, task=task)
    shipped = _tc_array(TaskConfig.from_dict(entry.tc) for entry in entries)
    np.testing.assert_array_equal(offsets[:, :2], shipped[:, :2])
    runs = [load_config(preset, task=task).run for preset in shipped_presets()]
    spec = get_task(task)
    drawn = {
        "evaluation": spec.evaluation_tcs(max(run.eval_episodes for run in runs)),
        "learning-curve": spec.training_curve_tcs(max(run.curve_episodes for run in runs)),
    }
    for name, tcs in drawn.items():
        gaps = np.abs(shipped[:, None, :] - _tc_array(tcs)[None, :, :]).max(axis=2)
        assert gaps.min() > 1e-9, (task, name, gaps.min())


def _copy_set(task: str, folder) -> dict:
    """Copy the task's shipped set into ``folder``; return its parsed tcs.json."""
    import json
    import shutil

    shutil.copytree(get_task(task).varied_demo_dir, folder)
    return json.loads((folder / "tcs.json").read_text())


def test_a_set_of_nineteen_demonstrations_is_refused_naming_the_folder(tmp_path):
    import json

    from distgprl.errors import UserInputError

    folder = tmp_path / "dcp_varied"
    index = _copy_set("dcp", folder)
    index["files"], index["tcs"] = index["files"][:19], index["tcs"][:19]
    (folder / "tcs.json").write_text(json.dumps(index))
    with pytest.raises(UserInputError, match=f"^{folder}: 19 demonstrations .* exactly 20$"):
        expert_demonstration_set("dcp", folder)


def test_a_demonstration_that_fails_or_collides_is_refused_naming_its_file(tmp_path):
    """A demonstration that does not complete the task for its TC (a DCP demonstration that
    holds the start pose), and one that collides (the nominal DBM demonstration on the TC of
    DBM's demo_06, where it hits an obstacle), each refuse the set with its file named."""
    from distgprl.errors import UserInputError
    from distgprl.skill.demos import save_demonstration

    dcp = tmp_path / "dcp_varied"
    _copy_set("dcp", dcp)
    held = load_demonstration(dcp / "demo_03.csv")
    save_demonstration(
        dcp / "demo_03.csv", held.times, np.tile(held.poses[0], (len(held.times), 1))
    )
    with pytest.raises(UserInputError, match="demo_03.csv: the demonstration does not complete"):
        expert_demonstration_set("dcp", dcp)

    dbm = tmp_path / "dbm_varied"
    _copy_set("dbm", dbm)
    nominal = load_demonstration(get_task("dbm").demo_path)
    save_demonstration(dbm / "demo_06.csv", nominal.times, nominal.poses)
    with pytest.raises(UserInputError, match="demo_06.csv: the demonstration collides"):
        expert_demonstration_set("dbm", dbm)


def test_a_missing_file_or_another_tasks_set_is_refused(tmp_path):
    from distgprl.errors import UserInputError

    folder = tmp_path / "dcp_varied"
    _copy_set("dcp", folder)
    (folder / "demo_11.csv").unlink()
    with pytest.raises(UserInputError, match="demo_11.csv: cannot read"):
        expert_demonstration_set("dcp", folder)
    with pytest.raises(UserInputError, match="made for task 'dbm', not 'dcp'"):
        expert_demonstration_set("dcp", get_task("dbm").varied_demo_dir)


def test_training_on_a_bad_set_exits_2_and_writes_nothing(tmp_path, monkeypatch):
    """`distgprl train --method promp-rrl` on a task whose demonstration set holds 19
    demonstrations: exit code 2, one line naming the folder, no run folder left behind."""
    import dataclasses
    import json

    from typer.testing import CliRunner

    from distgprl.cli import app
    from distgprl.sim import tasks

    folder = tmp_path / "demos" / "dcp_varied"
    index = _copy_set("dcp", folder)
    index["files"], index["tcs"] = index["files"][1:], index["tcs"][1:]
    (folder / "tcs.json").write_text(json.dumps(index))
    monkeypatch.setitem(
        tasks.TASKS, "dcp", dataclasses.replace(tasks.TASKS["dcp"], varied_demo_dir=folder)
    )
    load_task_promp.cache_clear()
    root = tmp_path / "results"
    args = ["train", "--preset", "ci", "--task", "dcp", "--method", "promp-rrl", "--seed", "0"]
    try:
        result = CliRunner().invoke(app, [*args, "--root", str(root)])
    finally:
        load_task_promp.cache_clear()
    assert result.exit_code == 2, result.output
    assert f"{folder}: 19 demonstrations" in result.output
    assert not [p for p in root.rglob("*") if p.is_file()]
