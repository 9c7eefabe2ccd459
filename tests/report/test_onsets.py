"""Learning-curve onsets (`distgprl.report.onsets`): the first step after the untrained
policy's at which a run's curve reaches the threshold, per reading and seed, and a control's
pre-registered rule applied to its own runs only."""

from __future__ import annotations

import pytest

from distgprl.report.onsets import onset_rows, onset_step, onset_texts, rule_verdict
from distgprl.studies import get_study

CONTROL = "operator-signal-uncoupled"
EARLY = [0.0, 0.2, 0.6, 0.8]  # reaches 0.5 at step 3 000: early (rule: by 4 500)
LATE = [0.0, 0.0, 0.0, 0.0, 0.7]  # at step 6 000: late
START = [0.6, 0.0, 0.0, 0.0]  # the untrained policy's 0.6, then the plateau: never


@pytest.mark.parametrize(
    ("success", "expected"),
    [(EARLY, 3000), (LATE, 6000), (START, None), ([0.0, 0.5], 1500), ([0.4, 0.49], None)],
)
def test_the_onset_is_the_first_curve_step_after_step_0_at_the_threshold(success, expected):
    """Step 0 (the untrained policy) never counts; reaching the threshold exactly does."""
    steps = [1500 * index for index in range(len(success))]
    assert onset_step(steps, success, 0.5) == expected


def test_every_panel_gets_a_row_per_seed_with_its_onset_and_both_policies(tmp_path, study_run):
    """Rows follow the curves' panels (Table I's reading, a study reading, NoCov); ``early``
    is the control rule's test on every panel's runs; best and final are the runs' own."""
    study_run(tmp_path, "paper", "dcp", "dist-gprl", 0, LATE, best=0.9)
    study_run(tmp_path, "paper", "dcp", "dist-gprl-nocov", 0, START)
    study_run(tmp_path, "operator-signal", "dcp", "dist-gprl", 1, EARLY)
    rows = onset_rows(tmp_path, get_study("operators"), ["dcp"])
    got = [(r["preset"], r["method"], r["seed"], r["onset_step"], r["early"]) for r in rows]
    assert got == [
        ("paper", "dist-gprl", 0, 6000, 0),
        ("operator-signal", "dist-gprl", 1, 3000, 1),
        ("paper", "dist-gprl-nocov", 0, "", 0),
    ]
    assert (rows[0]["best_success"], rows[0]["final_success"]) == (0.9, 0.7)


def test_a_study_of_every_trained_method_has_a_row_per_method_and_reading(tmp_path, study_run):
    """The reward-unit study acts on every trained method: its table lists each method (Table
    I's order) under Table I's unit and under the study's, no NoCov extra, no rule column."""
    from distgprl.report.onsets import onset_panels

    study = get_study("reward-unit")
    panels = onset_panels(study)
    assert len(panels) == 2 * len(study.methods)
    assert [p[1] for p in panels[:2]] == ["gprl", "gprl"]
    assert [p[0] for p in panels[:2]] == ["paper", "reward-unit-10"]
    study_run(tmp_path, "paper", "dcp", "gprl-h", 0, EARLY)
    study_run(tmp_path, "reward-unit-10", "dcp", "gprl-h", 0, LATE)
    _, markdown = onset_texts(tmp_path, study, ["dcp"], "paper")
    assert (
        "| GPRL-H: r_tc in units of one task (Table I) (`paper`) | 3 000: 0.80 (0.80) | 1/1 |"
        in (markdown)
    )
    assert "early" not in markdown


@pytest.mark.parametrize(
    ("curves", "verdict"),
    [
        ([EARLY] * 4 + [LATE], "reach"),
        ([EARLY] * 5, "reach"),
        ([EARLY] + [LATE] * 4, "coupling"),
        ([START] * 5, "coupling"),
        ([EARLY] * 2 + [LATE] * 3, "undecided at 5 seeds"),
        ([EARLY] * 3 + [LATE] * 2, "undecided at 5 seeds"),
        ([EARLY] * 4, "awaiting (4 of 5 runs finished)"),
        ([EARLY] * 4 + [LATE] + [EARLY] * 2, "reach"),  # seeds 5-6: outside the rule
        ([LATE] * 4 + [EARLY] * 3, "coupling"),
    ],
)
def test_the_controls_rule_decides_from_its_own_runs_only(tmp_path, study_run, curves, verdict):
    """4 or more of 5 control seeds early → reach, 1 or fewer → coupling, else undecided;
    fewer than 5 finished → awaiting; other readings' runs (here: signal, all early) and the
    control's DBM runs do not count."""
    study = get_study("operators")
    for seed, success in enumerate(curves):
        study_run(tmp_path, CONTROL, "dcp", "dist-gprl", seed, success)
    for seed in range(5):
        study_run(tmp_path, "operator-signal", "dcp", "dist-gprl", seed, EARLY)
        study_run(tmp_path, CONTROL, "dbm", "dist-gprl", seed, EARLY)
    result = rule_verdict(onset_rows(tmp_path, study, ["dcp", "dbm"]), study, CONTROL)
    assert result.verdict.startswith(verdict)
    assert result.runs == min(len(curves), 5)


def test_the_table_shows_each_seed_the_early_counts_and_the_controls_verdict(tmp_path, study_run):
    """A row per method and reading with runs: each seed's onset, best (final) success, how
    many reached the threshold at all and, on the rule's task, how many early; the control's
    verdict below; no finished run: no table."""
    study_run(tmp_path, "paper", "dcp", "dist-gprl", 0, LATE, best=0.9)
    study_run(tmp_path, "operator-signal", "dcp", "dist-gprl", 0, EARLY)
    study_run(tmp_path, CONTROL, "dcp", "dist-gprl", 0, START)
    csv_text, markdown = onset_texts(tmp_path, get_study("operators"), ["dcp"], "paper")
    assert csv_text.splitlines()[0].startswith("study,task,reading,preset,method,seed,onset")
    assert "| Dist-GPRL: zero-mean GP (Table I) (`paper`) | 6 000: 0.90 (0.70) | 1/1 | 0/1 |" in (
        markdown
    )
    assert (
        "| Dist-GPRL: per-axis signal (v5) (`operator-signal`) | 3 000: 0.80 (0.80) | 1/1 | 1/1 |"
        in (markdown)
    )
    assert "(`operator-signal-uncoupled`) | —: 0.00 (0.00) | 0/1 | 0/1 |" in markdown
    assert "**0 of 1 seeds learn early: awaiting (1 of 5 runs finished)**" in markdown
    assert onset_texts(tmp_path / "none", get_study("operators"), ["dcp"], "paper") is None
