"""Table II v8 (`distgprl.report.table2`): the paper's protocol first, the safety layer's
settings beside it; trial files told apart by the protocol their meta records."""

from __future__ import annotations

import numpy as np
import pytest

from distgprl.report.table2 import hardware_table, hardware_texts, select_trial_files
from distgprl.schema import write_csv

FIELDS = ["trial", "backend", "status", "success", "collision", "min_clearance", "execution_s"]


def _trials(root, name, outcomes, method="gprl", **meta):
    """A twin trial file of ``outcomes`` (status, success, collision, clearance m,
    execution s) with ``meta`` (preset ``p``, twin, seed 0, no sensor noise by default)."""
    rows = [dict(zip(FIELDS, (k, "twin", *o), strict=True)) for k, o in enumerate(outcomes)]
    values = {"preset": "p", "backend": "twin", "seed": 0, "sensor_noise": 0} | meta
    write_csv(root / "hardware" / method / name, rows, FIELDS, **values)


PAPER = [
    ("ok", 1, 0, 0.010, 2.0),
    ("stopped", 0, 1, -0.001, 1.0),  # a contact: a collision
    ("protective_stop", 0, 0, 0.030, 0.5),  # the UR5e stopped at its limit: a failure
    ("ok", 0, 0, 0.020, 2.0),
]
CHECKED = [("refused", 0, 0, 0.05, 0.0), ("ok", 1, 0, 0.02, 2.0)]


@pytest.fixture
def root(tmp_path):
    _trials(tmp_path, "a_paper.csv", PAPER, protocol="paper", repair=False)
    _trials(tmp_path, "b_off.csv", CHECKED, protocol="safety-layer", repair=False)
    _trials(tmp_path, "c_retime.csv", CHECKED[1:], repair=True)  # no protocol: v7's files
    return tmp_path


def test_the_papers_protocol_is_its_own_row_counting_protective_stops_and_collisions(root):
    """A paper-protocol file is never pooled with the safety layer's (a file without a
    protocol ran behind it); its protective stop is a failure without collision, counted
    apart from refusals; its contact stop is a collision."""
    rows = hardware_table(root, "p")
    assert [(r["protocol"], r["repair"]) for r in rows] == [
        ("paper", "–"),
        ("safety-layer", "off"),
        ("safety-layer", "retime"),
    ]
    paper = rows[0]
    assert (paper["trials"], paper["refused"], paper["protective_stops"]) == (4, 0, 1)
    assert paper["success_rate"] == pytest.approx(0.25)
    assert paper["collision_rate"] == pytest.approx(0.25)
    assert paper["min_clearance_p5"] == pytest.approx(
        np.percentile([0.010, -0.001, 0.030, 0.020], 5)
    )
    assert (rows[1]["refused"], rows[1]["protective_stops"]) == (1, 0)


def test_table_ii_puts_the_papers_protocol_first(root):
    """Markdown and LaTeX: one row per method with the paper's protocol's columns (trials,
    success, collision, protective stops, MinCl) first, then each safety-layer setting's;
    the CSV one row per protocol setting, the paper's first, with its protocol named."""
    csv_text, markdown, latex = hardware_texts(hardware_table(root, "p"), "p")
    header = markdown.splitlines()[2]
    assert header.startswith(
        "| Method | Backend | Noise | Paper: Trials | Paper: Success | Paper: Collision | "
        "Paper: Protective stops | Paper: MinCl (m) | Safety layer, repair off: Trials | "
        "Safety layer, repair off: Refused |"
    )
    assert header.index("Safety layer, repair off") < header.index("Safety layer, retime")
    minimum = np.percentile([0.010, -0.001, 0.030, 0.020], 5)
    paper_cells = f"| 4 | 0.25 [0.01, 0.81] | 0.25 [0.01, 0.81] | 1 | {minimum:.3f} |"
    assert f"| GPRL | twin | 0 {paper_cells} 2 | 1 |" in markdown
    assert "the paper's protocol" in markdown.splitlines()[0]
    assert "\\multicolumn{5}{c}{Paper} & \\multicolumn{5}{c}{Safety layer, repair off}" in latex
    assert "$\\pi$ rad/s" in latex and "95\\,\\% binomial interval" in latex
    lines = csv_text.splitlines()
    assert lines[0].startswith("method,backend,protocol,repair,sensor_noise,trials,refused,")
    assert [line.split(",")[2] for line in lines[1:]] == ["paper", "safety-layer", "safety-layer"]


def test_a_method_without_paper_trials_shows_dashes_in_the_papers_columns(tmp_path):
    _trials(tmp_path, "off.csv", CHECKED, protocol="safety-layer", repair=False)
    _, markdown, _ = hardware_texts(hardware_table(tmp_path, "p"), "p")
    assert "| GPRL | twin | 0 | – | – | – | – | – | 2 | 1 |" in markdown


def test_a_paper_file_and_a_safety_layer_file_of_one_setting_are_no_repeats(tmp_path):
    """The twin-repeat rule keeps one file per policy, seed and setting: the protocol is part
    of the setting (same seed, same bar positions, different protocol: both counted)."""
    _trials(tmp_path, "trials_twin_seed0_1.csv", CHECKED, protocol="paper", repair=False)
    _trials(tmp_path, "trials_twin_seed0_2.csv", CHECKED, protocol="safety-layer", repair=False)
    selection = select_trial_files(tmp_path, "p")
    assert len(selection.counted) == 2 and selection.excluded == ()


def test_the_note_says_which_trained_policy_the_counted_trials_ran(tmp_path):
    """From each file's provenance: a run's ``model.zip`` is its final policy, which Table II
    counts; another file is a given one, counted too; the shipped best actor (Table I's) is
    another named policy, counted in its own table beside Table II, and each table's note
    says how many files the other has; a reference's file (no policy) counts in both. The
    note sets the counted ones beside the policy Table I reports."""
    final = {"model": "/x/paper/dbm/gprl/seed0/model.zip", "model_sha256": "0"}
    given = {"model": "/x/other.zip", "model_sha256": "1", "policy": "given"}
    best = {"model": "/x/policy_best.pt", "policy": "best (shipped, curve step 300)"}
    _trials(tmp_path, "trials_twin_seed0_1.csv", CHECKED, protocol="paper", policy=final)
    _trials(tmp_path, "trials_twin_seed1_1.csv", CHECKED, protocol="paper", seed=1, policy=best)
    _trials(tmp_path, "trials_twin_seed2_1.csv", CHECKED, protocol="paper", seed=2, policy=given)
    _trials(tmp_path, "trials_twin_seed0_2.csv", CHECKED, method="demo", protocol="paper")
    selection = select_trial_files(tmp_path, "p")
    assert selection.note() == (
        "Trained policies run (trial files): the run's final policy (`model.zip`): 1 of 2 "
        "files, a policy file given by `--model`: 1 of 2 files; Table I reports each run's "
        "best trained policy (protocol v8 rule 2). Trial files of the best policy, tabulated "
        "apart in `table2_best_<preset>`: 1"
    )
    best_table = select_trial_files(tmp_path, "p", "best")
    assert [(method, meta["seed"]) for method, meta, _ in best_table.counted] == [
        ("gprl", 1),
        ("demo", 0),
    ]  # the reference's file runs no policy: it counts for every table
    assert best_table.note().startswith(
        "Trained policies run (trial files): the run's shipped best policy (Table I's): 1 of 1"
    )
    assert "Trial files of the final policy, tabulated apart in `table2_<preset>`: 1" in (
        best_table.note()
    )
    assert select_trial_files(tmp_path / "none", "p").note() == ""


def test_the_best_policys_table_is_written_beside_table_ii_only_where_trials_ran_it(
    tmp_path, study_run
):
    """`write_tables`: ``table2_best_<preset>`` exists only where a trained policy's trials
    ran the best policy (the references' files, which run none, do not make one), of the
    noise-free settings its trials run; its title says whose policies it holds, and Table
    II's note counts its files."""
    from distgprl.report.runs import current_hash
    from distgprl.report.tables import write_tables

    study_run(tmp_path, "paper", "dbm", "gprl", 0, [0.0, 0.5])
    current = current_hash("dbm", "gprl", 0, "paper")
    paper = {"preset": "paper", "protocol": "paper"}
    _trials(tmp_path, "trials_twin_seed0_d.csv", PAPER, method="demo", **paper)
    noisy = {"preset": "paper", "repair": True, "sensor_noise": 2}  # Table II's noise series
    _trials(tmp_path, "trials_twin_seed0_n.csv", CHECKED, method="demo", **noisy)
    final = {"run_config_hash": current, "model": "/r/model.zip"}
    _trials(tmp_path, "trials_twin_seed0_f.csv", PAPER, policy=final, **paper)
    out = tmp_path / "out"
    written = {path.name for path in write_tables(tmp_path, "paper", out)}
    assert "table2_paper.md" in written and "table2_best_paper.md" not in written
    best = {"run_config_hash": current, "model": "/r/policy_best.pt", "policy": "best (x)"}
    _trials(tmp_path, "trials_twin_seed0_b.csv", PAPER[:2], policy=best, **paper)
    written = {path.name for path in write_tables(tmp_path, "paper", out)}
    assert {"table2_best_paper.md", "table2_best_paper.csv", "table2_best_paper.tex"} <= written
    markdown = (out / "table2_best_paper.md").read_text()
    assert markdown.startswith("Table II of the best policies, Table I's (beside Table II")
    assert "| GPRL | twin | 0 | 2 |" in markdown and "| Demo (no adaptation) | twin | 0 | 4 |" in (
        markdown
    )
    assert "| Demo (no adaptation) | twin | 2 |" not in markdown  # the best's settings only
    assert "| Demo (no adaptation) | twin | 2 |" in (out / "table2_paper.md").read_text()
    assert "Trial files of the best policy, tabulated apart in `table2_best_<preset>`: 1" in (
        (out / "table2_paper.md").read_text()
    )
    assert "tab:hardware_results_best" in (out / "table2_best_paper.tex").read_text()
