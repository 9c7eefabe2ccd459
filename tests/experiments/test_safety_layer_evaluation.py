"""Evaluation in simulation with the safety layer in the loop (`safety_layer_evaluation`), on
the ci preset's untrained references (`demo`, `promp-nominal`: no training needed)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from distgprl.experiments import safety_layer_evaluation as repaired
from distgprl.experiments.factories import make_env
from distgprl.experiments.rollout import evaluate_policy
from distgprl.identity import resolve_run
from distgprl.limits import SafetyLimits
from distgprl.safety_layer.retime import RepairConfig
from distgprl.schema import (
    REPAIR_EVALUATION_FIELDS,
    read_csv,
    read_json,
    repair_evaluation_file_names,
    run_dir,
)

#: Limits no plan of the references comes near (every window passes unchanged).
LOOSE = SafetyLimits(
    workspace_lower=(-5.0, -5.0, -5.0),
    workspace_upper=(5.0, 5.0, 5.0),
    max_joint_speed=1e9,
    max_joint_acceleration=1e12,
    max_tcp_speed=1e9,
    min_clearance=-1.0,
)


@pytest.fixture(scope="module")
def dbm_demo():
    env = make_env(resolve_run("dbm", "demo", 0, "ci"))
    yield env
    env.close()


@pytest.fixture(scope="module")
def first_tc(dbm_demo):
    return dbm_demo.spec_task.evaluation_tcs(1)[0]


@pytest.mark.parametrize("method", ["demo", "promp-rrl-windowed"])
def test_windows_that_pass_are_executed_exactly_as_the_env_steps_them(method):
    """With limits no plan violates, every executed window's decision is ``none`` and the episode's
    success, collision, signed clearance and peak joint speed equal the plain evaluation's
    (`AdaptationEnv.step` / `ResidualEnv`) bit for bit."""
    env = make_env(resolve_run("dbm", method, 0, "ci"))
    try:
        tcs = env.spec_task.evaluation_tcs(2)
        plain = evaluate_policy(env, tcs)
        layered = [repaired.run_repaired_episode(env, tc, None, LOOSE) for tc in tcs]
    finally:
        env.close()
    for a, b in zip(plain, layered, strict=True):
        # a collision ends the episode (v5): the windows up to it
        assert set(b["repair"].split(";")) == {"none"} and b["refused"] == 0
        for key in ("success", "completed", "collision", "min_signed_clearance"):
            assert a[key] == b[key], key
        assert a["peak_joint_speed"] == b["peak_joint_speed"]


def test_a_plan_above_the_joint_speed_limit_is_retimed_and_executed(dbm_demo, first_tc):
    """Under a joint speed limit below the demonstration's peak (~1 rad/s), windows are
    retimed (time added > 0), none is refused, the episode runs to its end and never
    commands a joint faster than the limit."""
    plain = evaluate_policy(dbm_demo, [first_tc])[0]
    limit = 0.6 * plain["peak_joint_speed"]
    limits = replace(SafetyLimits(), max_joint_speed=limit)
    row = repaired.run_repaired_episode(dbm_demo, first_tc, None, limits)
    decisions = row["repair"].split(";")
    assert "retimed" in decisions and "refused" not in decisions and len(decisions) == 3
    assert row["refused"] == 0 and row["refused_window"] == ""
    assert row["time_added_s"] > 0.0
    assert row["executed_s"] == pytest.approx(
        dbm_demo.skill.duration + row["time_added_s"], abs=1e-9
    )
    assert row["peak_joint_speed"] <= limit * (1 + 1e-6) < plain["peak_joint_speed"]


def test_a_plan_the_repair_cannot_save_is_refused_with_its_reason(dbm_demo, first_tc):
    """A joint speed limit no retiming within ``max_added_s`` can meet refuses the first
    window: nothing moves, the episode is neither a success nor a collision, and the row
    names the limit and the reason."""
    limits = replace(SafetyLimits(), max_joint_speed=0.005)
    config = RepairConfig(max_added_s=1.0)
    row = repaired.run_repaired_episode(dbm_demo, first_tc, None, limits, config)
    assert row["repair"] == "refused" and row["refused"] == 1 and row["refused_window"] == 1
    assert row["refused_limits"] == "joint_speed"
    assert row["refusal_reason"].startswith("joint_speed: ")
    assert (row["success"], row["collision"], row["executed_s"]) == (0, 0, 0.0)


def test_a_workspace_violation_is_refused_without_retiming(dbm_demo, first_tc):
    """A limit repair does not fix (the workspace) is refused at once, the reason naming it."""
    lower, upper = SafetyLimits().workspace_lower, SafetyLimits().workspace_upper
    limits = replace(SafetyLimits(), workspace_upper=(upper[0], upper[1], lower[2] + 0.01))
    row = repaired.run_repaired_episode(dbm_demo, first_tc, None, limits)
    assert row["repair"] == "refused" and row["refused_limits"].split(",")[0] == "workspace"
    assert row["time_added_s"] == 0.0 and row["success"] == 0


def test_the_files_have_the_columns_and_the_same_seed_gives_the_same_result(tmp_path):
    """evaluate_with_repair writes evaluation_repair_n3.csv (every REPAIR_EVALUATION_FIELDS
    column, one row per TC) and its summary beside the plain evaluation (which it does not
    write); two evaluations give the same rows, timings aside."""
    rows = []
    for root in (tmp_path / "a", tmp_path / "b"):
        summary = repaired.evaluate_with_repair(
            "dbm", "demo", 0, "ci", episodes=3, root=root, show_progress=False
        )
        folder = run_dir(root, "ci", "dbm", "demo", 0)
        csv_name, summary_name = repair_evaluation_file_names(3)
        meta, table = read_csv(folder / csv_name)
        assert list(table[0]) == list(REPAIR_EVALUATION_FIELDS) and len(table) == 3
        assert meta["repair_mode"] == "repair" and meta["config_hash"]
        assert read_json(folder / summary_name)["summary"]["episodes"] == 3
        assert not (folder / "evaluation_n3.csv").exists()
        for key in ("success_rate", "collision_rate", "refused_rate", "mean_time_added_s"):
            assert 0.0 <= summary[key] <= (1.0 if key.endswith("rate") else 10.0)
        rows.append([{k: v for k, v in r.items() if not k.endswith("_ms")} for r in table])
    assert rows[0] == rows[1]


def test_summary_counts_refusals_and_time_added():
    """The summary's rates are per episode, the time added is averaged over all episodes
    and over the retimed ones, the windows are counted per decision."""
    base = {k: "" for k in REPAIR_EVALUATION_FIELDS}

    def row(success, collision, refused, added, decisions, limits="", moved=1.0):
        return {
            **base,
            "success": success,
            "completed": success,
            "collision": collision,
            "refused": refused,
            "time_added_s": added,
            "max_displacement_m": 0.0,
            "repair": decisions,
            "refused_limits": limits,
            "executed_s": moved,
            "min_clearance": 0.01,
        }

    rows = [
        row(1, 0, 0, 0.0, "none;none;none"),
        row(0, 0, 1, 0.4, "retimed;refused", "clearance", 2.0),
        row(0, 1, 0, 0.2, "none;retimed;none"),
        row(0, 0, 1, 0.0, "refused", "joint_speed,clearance", 0.0),
    ]
    summary = repaired.summarise_repaired(rows)
    assert summary["success_rate"] == 0.25 and summary["collision_rate"] == 0.25
    assert summary["refused_rate"] == 0.5
    assert summary["mean_time_added_s"] == pytest.approx(0.15)
    assert summary["mean_time_added_when_retimed_s"] == pytest.approx(0.3)
    assert (summary["windows_none"], summary["windows_retimed"]) == (5, 2)
    assert summary["windows_refused"] == 2 and summary["refused_for_clearance"] == 2
    assert summary["refused_for_joint_speed"] == 1


def test_dcp_limits_reach_the_table_top_and_dbm_keeps_the_hardware_limits():
    """DBM's layer enforces the hardware cell's limits; DCP's only lowers the workspace floor
    to the table top and the clearance limit to 2 mm."""
    assert repaired.simulation_safety_limits("dbm") == SafetyLimits()
    dcp = repaired.simulation_safety_limits("dcp")
    assert dcp.workspace_lower[2] == 0.0 and dcp.min_clearance == repaired.DCP_TABLE_CLEARANCE
    assert replace(dcp, workspace_lower=SafetyLimits().workspace_lower, min_clearance=0.005) == (
        SafetyLimits()
    )


def test_repair_mode_follows_the_configuration():
    """The file tag says what the layer did: push, retime only, or check only."""
    assert repaired.repair_mode(RepairConfig()) == "repair"
    assert repaired.repair_mode(RepairConfig(repair=True)) == "push"
    assert repaired.repair_mode(RepairConfig(retime=False)) == "check"


def test_residual_control_methods_get_twin_trials_but_no_simulated_repair_evaluation(tmp_path):
    """The simulated safety-layer evaluation refuses environment v6's residual-control
    methods with the stated reason and its follow-up is not due for them; their twin trials
    are (the twin checks them one 0.1 s step at a time): the reference at once, the trained
    method once its model is on disk."""
    from distgprl.errors import UserInputError
    from distgprl.experiments.follow_ups import repairs_due, trials_due
    from distgprl.experiments.jobs import Job
    from distgprl.methods import NO_SAFETY_LAYER

    with pytest.raises(UserInputError) as raised:
        repaired.evaluate_with_repair("dbm", "promp-rrl", 0, "ci", root=tmp_path)
    assert str(raised.value) == f"promp-rrl: {NO_SAFETY_LAYER}"
    for method in ("promp-rrl", "promp-nominal"):
        job = Job("dbm", method, 0, "ci", str(tmp_path), twin_trials=2, repair_evaluations=True)
        assert not repairs_due(job)
        assert trials_due(job) == (method == "promp-nominal")  # promp-rrl: no model.zip yet
    from distgprl.experiments.table2_trials import NOISE_LEVELS, model_path, table2_settings

    model_path(tmp_path, "ci", "promp-rrl", 0).parent.mkdir(parents=True)
    model_path(tmp_path, "ci", "promp-rrl", 0).write_bytes(b"")  # trained: its model on disk
    assert trials_due(Job("dbm", "promp-rrl", 0, "ci", str(tmp_path), twin_trials=2))
    # repair on and off, and repair on at every sensor-noise level (Table II's noise curve)
    assert len(table2_settings("promp-rrl")) == 3 + len(NOISE_LEVELS)
