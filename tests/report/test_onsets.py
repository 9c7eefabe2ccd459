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


def test_a_study_of_every_trained_method_has_a_row_per_method_and_reading(
    tmp_path, study_run, unit_study_preset
):
    """A study of every trained method (a reward constant's): its table lists each method
    (Table I's order) under Table I's reading and under the study's, no NoCov extra, no rule
    column."""
    from distgprl.report.onsets import onset_panels

    study = unit_study_preset
    (reading,) = study.presets
    panels = onset_panels(study)
    assert len(panels) == 2 * len(study.methods)
    assert [p[1] for p in panels[:2]] == ["gprl", "gprl"]
    assert [p[0] for p in panels[:2]] == ["paper", reading]
    study_run(tmp_path, "paper", "dcp", "gprl-h", 0, EARLY)
    study_run(tmp_path, reading, "dcp", "gprl-h", 0, LATE)
    _, markdown = onset_texts(tmp_path, study, ["dcp"], "paper")
    assert (
        "| GPRL-H: r_tc in tenths of a task (Table I) (`paper`) | 3 000: 0.80 (0.80) | 1/1 |"
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
def test_the_controls_first_rule_decides_from_its_own_runs_only(
    tmp_path, study_run, curves, verdict
):
    """Stage 1: 4 or more of seeds 0-4 early → reach, 1 or fewer → coupling, else undecided;
    fewer than 5 finished → awaiting; other readings' runs (here: signal, all early), the
    control's DBM runs and its seeds beyond 4 do not count."""
    study = get_study("operators")
    for seed, success in enumerate(curves):
        study_run(tmp_path, CONTROL, "dcp", "dist-gprl", seed, success)
    for seed in range(5):
        study_run(tmp_path, "operator-signal", "dcp", "dist-gprl", seed, EARLY)
        study_run(tmp_path, CONTROL, "dbm", "dist-gprl", seed, EARLY)
    _, runs, got = rule_verdict(onset_rows(tmp_path, study, ["dcp", "dbm"]), study, "stage 1")
    assert got.startswith(verdict)
    assert runs == min(len(curves), 5)


@pytest.mark.parametrize(
    ("signal", "control", "verdict"),
    [
        (5, 8, "reach"),
        (4, 10, "reach"),
        (5, 2, "coupling"),
        (4, 0, "coupling"),
        (5, 3, "both"),
        (5, 7, "both"),
        (3, 10, "void: stage 2 replication gave not replicated"),
        (0, 0, "void: stage 2 replication gave not replicated"),
    ],
)
def test_the_second_stage_reads_new_seeds_and_needs_the_signal_reading_replicated(
    tmp_path, study_run, signal, control, verdict
):
    """Stage 2: the signal reading early on 4 or more of seeds 5-9 replicates its effect,
    else the control's rule is void; the control's seeds 5-14 decide: 8 or more early →
    reach, 2 or fewer → coupling, between → both. Seeds 0-4 (here all late for the control,
    all early for the signal reading) do not count."""
    study = get_study("operators")
    for seed in range(5):
        study_run(tmp_path, CONTROL, "dcp", "dist-gprl", seed, LATE)
        study_run(tmp_path, "operator-signal", "dcp", "dist-gprl", seed, EARLY)
    for index, seed in enumerate(range(5, 10)):
        study_run(
            tmp_path, "operator-signal", "dcp", "dist-gprl", seed, EARLY if index < signal else LATE
        )
    for index, seed in enumerate(range(5, 15)):
        study_run(tmp_path, CONTROL, "dcp", "dist-gprl", seed, EARLY if index < control else START)
    rows = onset_rows(tmp_path, study, ["dcp"])
    early, runs, got = rule_verdict(rows, study, "stage 2")
    assert (early, runs) == (control, 10)
    assert got.startswith(verdict)
    replication = rule_verdict(rows, study, "stage 2 replication")[2]
    assert replication.startswith("replicated" if signal >= 4 else "not replicated")
    assert rule_verdict(rows, study, "stage 1")[2].startswith("coupling")


def test_the_second_stage_awaits_its_runs_and_the_replications(tmp_path, study_run):
    """All ten control runs in but the signal reading's seeds 5-9 not: stage 2 awaits them
    (not void); a control run missing: awaiting with the count."""
    study = get_study("operators")
    for seed in range(5, 15):
        study_run(tmp_path, CONTROL, "dcp", "dist-gprl", seed, EARLY)
    verdict = rule_verdict(onset_rows(tmp_path, study, ["dcp"]), study, "stage 2")[2]
    assert verdict.startswith("awaiting (10 of 10 runs finished; stage 2 replication")
    (tmp_path / CONTROL / "dcp" / "dist-gprl" / "seed14" / "done.json").unlink()
    verdict = rule_verdict(onset_rows(tmp_path, study, ["dcp"]), study, "stage 2")[2]
    assert verdict.startswith("awaiting (9 of 10 runs finished")
    for seed in range(5, 10):  # the replication fails: void, whatever the control's runs say
        study_run(tmp_path, "operator-signal", "dcp", "dist-gprl", seed, LATE)
    verdict = rule_verdict(onset_rows(tmp_path, study, ["dcp"]), study, "stage 2")[2]
    assert verdict == "void: stage 2 replication gave not replicated"


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


def test_seeds_beyond_the_studys_get_their_own_table_and_every_rule_its_line(tmp_path, study_run):
    """The study's table has seeds 0-4 only; a rule's further seeds a table of their own
    (every run in the CSV); each rule's verdict and each ruled reading's count over all its
    seeds are stated."""
    study_run(tmp_path, "operator-signal", "dcp", "dist-gprl", 0, EARLY)
    study_run(tmp_path, "operator-signal", "dcp", "dist-gprl", 5, LATE)
    study_run(tmp_path, CONTROL, "dcp", "dist-gprl", 7, EARLY)
    csv_text, markdown = onset_texts(tmp_path, get_study("operators"), ["dcp"], "paper")
    assert len(csv_text.splitlines()) == 1 + 3
    main, beyond = markdown.split("**DCP, seeds beyond the study's 0–4**")
    assert "| Run | seed 0 | reached 0.5 | early (by step 4 500) |" in main
    assert "| Run | seed 5 | seed 7 | reached 0.5 | early (by step 4 500) |" in beyond
    assert "(`operator-signal`) | 6 000: 0.70 (0.70) |  | 1/1 | 0/1 |" in beyond
    assert "(`operator-signal-uncoupled`) |  | 3 000: 0.80 (0.80) | 1/1 | 1/1 |" in beyond
    assert "**per-axis signal (v5), stage 2 replication** (its rule" in markdown
    assert "on DCP seeds 5–14 a run learns early" in markdown
    assert "8 or more of 10 → reach, 2 or fewer → coupling, otherwise both; needs stage 2" in (
        markdown
    )
    assert "**1 of 1 seeds learn early: awaiting (1 of 10 runs finished; stage 2 replication" in (
        markdown
    )
    assert "signal reach, uncoupled (control), every finished seed on DCP" in markdown
    assert "per-axis signal (v5), every finished seed on DCP (descriptive; no rule reads this " in (
        markdown.replace("\n", " ")
    )
