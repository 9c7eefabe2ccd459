"""The operator study's outputs from a result tree: `write_tables` writes the claims per
reading and `write_curves` the sensitivity figure, both from the result files alone
(`distgprl.report.robustness`, `distgprl.report.sensitivity`)."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.report.curves import write_curves
from distgprl.report.frame import load_frames
from distgprl.report.runs import current_hash
from distgprl.report.sensitivity import reading_gains
from distgprl.report.tables import write_tables
from distgprl.schema import PROGRESS_FIELDS, read_csv, write_csv, write_json
from distgprl.studies import get_study

STUDY = get_study("operators")
GLOBAL = "Windowed adaptation beats global"


def _run(root, preset, task, method, seed, success):
    folder = root / preset / task / method / f"seed{seed}"
    summary = {"success_rate": success, "collision_rate": 1.0 - success}
    summary.update(min_clearance_p5=0.01, min_signed_clearance_p5=0.01)
    summary.update(completion_rate=success, mean_kinematic_retention=0.8)
    config_hash = current_hash(task, method, seed, preset)
    for name in ("summary.json", "summary_best.json"):
        write_json(folder / name, {"summary": summary}, config_hash=config_hash)
    rows = []
    for index, point in enumerate([0.0, success / 2, success, success]):
        row = dict.fromkeys(PROGRESS_FIELDS, "")
        row.update(step=1500 * index, success_rate=point, collision_rate=0.0)
        rows.append(row)
    write_csv(folder / "progress.csv", rows, PROGRESS_FIELDS, config_hash=config_hash)


def _reach(root, gains):
    rows = [
        {
            "preset": preset,
            "reading": preset,
            "task": "dcp",
            "method": "dist-gprl",
            "axis": axis,
            "mean_gain": gain if axis != "z" else 99.0,  # z: the TCs do not vary it
            "tc_range_m": 0.2 if axis != "z" else 0.0,
        }
        for preset, gain in gains.items()
        for axis in ("x", "y", "z")
    ]
    write_json(root / STUDY.name / "reach.json", {"study": STUDY.name, "rows": rows})


@pytest.fixture
def tree(tmp_path):
    """DCP: Table I's Dist-GPRL 0.9 and Global 0.3 over 3 seeds; Dist-GPRL under
    operator-signal 0.1 (3 seeds); the reach file of every reading."""
    jitter = np.array([-0.02, 0.0, 0.02])
    for seed in range(3):
        _run(tmp_path, "paper", "dcp", "dist-gprl", seed, 0.9 + jitter[seed])
        _run(tmp_path, "paper", "dcp", "dist-gprl-global", seed, 0.3 + jitter[seed])
        _run(tmp_path, "paper", "dcp", "dist-gprl-nocov", seed, 0.6 + jitter[seed])
    for seed in range(3):
        _run(tmp_path, "operator-signal", "dcp", "dist-gprl", seed, 0.1 + jitter[seed])
    _reach(tmp_path, {"paper": 1.0, "operator-signal": 0.2, "operator-unit": 1.01})
    return tmp_path


def test_the_claims_per_reading_come_from_each_readings_runs(tree):
    """The windowed claim is reproduced on Table I's runs and refuted on operator-signal's
    (Dist-GPRL 0.1 vs Table I's Global 0.3): reading-dependent; a reading without Dist-GPRL
    runs is not run."""
    written = {p.name for p in write_tables(tree, "paper", tree / "out")}
    assert {"claims_robustness_paper.csv", "claims_robustness_paper.md"} <= written
    _, rows = read_csv(tree / "out" / "claims_robustness_paper.csv")
    windowed = {r["reading"]: r["verdict"] for r in rows if r["claim"] == GLOBAL}
    table_one = "zero-mean GP (Table I)"  # the one study read beside `paper`
    assert windowed[table_one] == "reproduced"
    assert windowed["per-axis signal (v5)"] == "refuted"
    _, claims = read_csv(tree / "out" / "claims_paper.csv")  # Table I's own claims: every seed
    assert any(r["claim"] == GLOBAL for r in claims)
    assert windowed["unit variance (v4)"] == "not run under this reading"  # Dist-GPRL not run
    assert windowed["across"].startswith(f"reading-dependent: reproduced under {table_one}")


def test_the_sensitivity_figure_is_drawn_from_the_reach_file_and_the_runs(tree):
    """PNG and PDF are written with the readings that have runs; without the reach file the
    figure is removed, not left stale."""
    out = tree / "out"
    names = {p.name for p in write_curves(tree, "paper", out)}
    assert {"sensitivity_operators_paper.png", "sensitivity_operators_paper.pdf"} <= names
    assert (out / "sensitivity_operators_paper.png").stat().st_size > 10_000
    (tree / STUDY.name / "reach.json").unlink()
    names = {p.name for p in write_curves(tree, "paper", out)}
    assert not any(name.startswith("sensitivity_") for name in names)
    assert not (out / "sensitivity_operators_paper.png").exists()


def test_a_readings_gain_averages_the_axes_the_tcs_vary(tree):
    """z (TC range 0) is left out of the mean gain."""
    from distgprl.schema import read_json

    gains = reading_gains(read_json(tree / STUDY.name / "reach.json"), "dist-gprl")
    assert gains[("operator-signal", "dcp")] == pytest.approx(0.2)
    assert gains[("paper", "dcp")] == pytest.approx(1.0)


def test_a_control_is_drawn_hollow_beside_the_reading_with_its_gain(tree):
    """The uncoupled-signal control has the signal reading's gain: its point keeps that x in
    data units but is drawn shifted right on the page (another transform), hollow; every
    reading's point is drawn at its own x unshifted."""
    from matplotlib.colors import to_rgba

    from distgprl.report.sensitivity import plot_sensitivity
    from distgprl.report.table1 import collect_scores

    for seed in range(3):
        _run(tree, "operator-signal-uncoupled", "dcp", "dist-gprl", seed, 0.5)
    _reach(tree, {"paper": 1.0, "operator-signal": 0.2, "operator-signal-uncoupled": 0.2})
    scores_of = {r.preset: collect_scores(load_frames(tree, r.preset)) for r in STUDY.all_readings}
    fig = plot_sensitivity(tree, STUDY, scores_of)
    success = fig.axes[0]
    points = [line for line in success.get_lines() if line.get_marker() in tuple("o^sDvP")]
    control = [line for line in points if to_rgba(line.get_markerfacecolor()) == (1, 1, 1, 1)]
    readings = [line for line in points if line not in control]
    assert len(control) == 1 and control[0].get_xdata()[0] == pytest.approx(0.2)
    assert control[0].get_transform() != success.transData
    assert all(line.get_transform() == success.transData for line in readings)
    assert sorted(line.get_xdata()[0] for line in readings) == pytest.approx([0.2, 1.0])


def test_runs_at_seeds_beyond_the_studys_change_no_claim_per_reading(tree):
    """Seeds 5-9 of a reading (a stage-2 rule's runs; `Study.seeds` is 0-4) stay out of the
    claims per reading: the signal reading stays refuted on its three seeds although five
    better runs lie beside them."""
    for seed in range(5, 10):
        _run(tree, "operator-signal", "dcp", "dist-gprl", seed, 0.95)
        _run(tree, "paper", "dcp", "dist-gprl-global", seed, 0.0)  # nor Table I's beyond 0-4
    write_tables(tree, "paper", tree / "out")
    _, rows = read_csv(tree / "out" / "claims_robustness_paper.csv")
    windowed = {r["reading"]: r["verdict"] for r in rows if r["claim"] == GLOBAL}
    assert windowed["per-axis signal (v5)"] == "refuted"
