"""The onset figure (`distgprl.report.onset_figure`): the onset table drawn, one marker per
finished run at its onset step or in the "never" band, rows in the table's order, filled for
the study's seeds and hollow for a rule's further seeds, the rule's ``by_step`` on its task."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import pytest

from distgprl.report.figure_files import write_or_remove_figure
from distgprl.report.onset_figure import (
    NEVER_BAND,
    NEVER_X,
    plot_onset_figure,
    seed_marker,
    seed_offsets,
)
from distgprl.report.onsets import onset_panels, onset_rows, run_label
from distgprl.studies import get_study

CONTROL = "operator-signal-uncoupled"
EARLY = [0.0, 0.2, 0.6, 0.8]  # reaches 0.5 at step 3 000
LATE = [0.0, 0.0, 0.0, 0.0, 0.7]  # at step 6 000
NEVER = [0.6, 0.0, 0.0, 0.0]  # the untrained policy's 0.6 does not count: never
DCP_STEPS = 30_000  # the paper preset's DCP run length (distgprl/presets/paper.yaml)


def markers(ax):
    """{gid: Line2D} of the run markers of ``ax``."""
    return {line.get_gid(): line for line in ax.lines if (line.get_gid() or "").startswith("onset")}


def marker_gid(preset, method, task, seed):
    """The ``gid`` by which a reader of the figure finds a run's marker."""
    return f"onset {preset} {method} {task} seed{seed}"


def point(line):
    """(x, y) of a one-point marker."""
    (x,), (y,) = line.get_xdata(), line.get_ydata()
    return float(x), float(y)


@pytest.fixture
def operators(tmp_path, study_run):
    """DCP: Table I's Dist-GPRL seed 0 (late) and 1 (never), the signal reading's seeds 0
    (early) and 5 (early; a seed only a rule reads), NoCov seed 0 (never); DBM: Table I's
    Dist-GPRL seed 0 (early)."""
    study_run(tmp_path, "paper", "dcp", "dist-gprl", 0, LATE)
    study_run(tmp_path, "paper", "dcp", "dist-gprl", 1, NEVER)
    study_run(tmp_path, "operator-signal", "dcp", "dist-gprl", 0, EARLY)
    study_run(tmp_path, "operator-signal", "dcp", "dist-gprl", 5, EARLY)
    study_run(tmp_path, "paper", "dcp", "dist-gprl-nocov", 0, NEVER)
    study_run(tmp_path, "paper", "dbm", "dist-gprl", 0, EARLY)
    return tmp_path


def test_every_finished_run_is_one_marker(operators):
    """The count returned, the markers on the axes and the onset table's rows are equal, one
    marker per (panel, task, seed) of `onset_rows`."""
    study = get_study("operators")
    rows = onset_rows(operators, study, ["dcp", "dbm"])
    fig, drawn = plot_onset_figure(operators, study, ["dcp", "dbm"], "paper")
    dcp, dbm = fig.axes[:2]
    expected = {marker_gid(r["preset"], r["method"], r["task"], r["seed"]) for r in rows}
    assert drawn == len(rows) == 6
    assert set(markers(dcp)) | set(markers(dbm)) == expected
    assert len(markers(dcp)) == 5 and len(markers(dbm)) == 1
    plt.close(fig)


def test_a_marker_sits_at_its_onset_step_or_in_the_never_band(operators):
    """x is the onset step (3 000 early, 6 000 late); a run whose curve never reaches 0.5
    after step 0 is at the "never" position, inside the shaded band right of the run length
    (30 000 on DCP), beyond every step of the axis range."""
    fig, _ = plot_onset_figure(operators, get_study("operators"), ["dcp"], "paper")
    (ax,) = fig.axes
    drawn = markers(ax)
    assert point(drawn[marker_gid("operator-signal", "dist-gprl", "dcp", 0)])[0] == 3000
    assert point(drawn[marker_gid("paper", "dist-gprl", "dcp", 0)])[0] == 6000
    never = point(drawn[marker_gid("paper", "dist-gprl", "dcp", 1)])[0]
    assert never == point(drawn[marker_gid("paper", "dist-gprl-nocov", "dcp", 0)])[0]
    assert never == pytest.approx(NEVER_X * DCP_STEPS)
    (band,) = ax.patches
    low, high = band.get_x(), band.get_x() + band.get_width()
    assert DCP_STEPS < low < never < high
    assert ax.get_xlim()[1] == pytest.approx(high)
    labels = [t.get_text() for t in ax.get_xticklabels()]
    assert labels[-1] == "never" and "30 000" in labels
    plt.close(fig)


def test_rows_keep_the_tables_order_and_each_run_sits_in_its_row(operators):
    """Rows top to bottom are the table's panels with a run (Table I's reading, the signal
    reading, NoCov; readings without runs left out), labelled as the table names them; each
    marker lies within its row, the seeds of a row at distinct heights, seed 0 above seed 5."""
    study = get_study("operators")
    fig, _ = plot_onset_figure(operators, study, ["dcp"], "paper")
    (ax,) = fig.axes
    panels = [p for p in onset_panels(study) if p[0] in ("paper", "operator-signal")]
    panels = [p for p in panels if p[1] == "dist-gprl" or p[0] == "paper"]
    labels = [t.get_text() for t in ax.get_yticklabels()]
    assert labels == [run_label(study, method, reading) for _, method, reading in panels]
    assert labels[1] == "Dist-GPRL: per-axis signal (v5)"
    assert ax.get_ylim()[0] > ax.get_ylim()[1]  # the first row at the top
    drawn = markers(ax)
    for index, (preset, method, _) in enumerate(panels):
        for gid, line in drawn.items():
            if gid.startswith(f"onset {preset} {method} "):
                assert abs(point(line)[1] - index) < 0.5, gid
    signal = [point(drawn[marker_gid("operator-signal", "dist-gprl", "dcp", s)]) for s in (0, 5)]
    assert signal[0][0] == signal[1][0] and signal[0][1] < signal[1][1]
    plt.close(fig)


def test_seed_offsets_are_distinct_inside_the_row_and_fixed_by_seed():
    """Offsets are spread over less than a row, in seed order, the same for the same seeds;
    a single seed sits on the row's line."""
    offsets = seed_offsets([4, 0, 2, 1, 3, 0])
    assert list(offsets) == [0, 1, 2, 3, 4]
    values = list(offsets.values())
    assert values == sorted(values) and len(set(values)) == 5
    assert max(values) - min(values) < 1.0 and values[2] == pytest.approx(0.0)
    assert seed_offsets([0, 1, 2, 3, 4]) == offsets
    assert seed_offsets([7]) == {7: 0.0}


def test_seeds_beyond_the_colour_cycle_differ_in_shape(operators):
    """Fifteen seeds (the control's 0-14) draw fifteen distinct (colour, shape) markers, so no
    two seeds' runs look alike where the colours cycle."""
    study = get_study("operators")
    styles = {(m["color"], m["marker"]) for m in (seed_marker(k, study) for k in range(15))}
    assert len(styles) == 15


def test_the_studys_seeds_are_filled_and_a_rules_further_seeds_hollow(operators):
    """Seed 0 (one of the study's seeds 0-4) is a filled marker, seed 5 (read only by the
    signal reading's replication rule) a hollow one of the same kind; the legend says which
    is which."""
    fig, _ = plot_onset_figure(operators, get_study("operators"), ["dcp"], "paper")
    drawn = markers(fig.axes[0])
    filled = drawn[marker_gid("operator-signal", "dist-gprl", "dcp", 0)]
    hollow = drawn[marker_gid("operator-signal", "dist-gprl", "dcp", 5)]
    assert filled.get_markerfacecolor() == filled.get_markeredgecolor()
    assert hollow.get_markerfacecolor() == "none"
    (legend,) = fig.legends
    title = legend.get_title().get_text()
    assert "filled: the study's seeds (0–4)" in title and "hollow: a further seed" in title
    labels = [t.get_text() for t in legend.get_texts()]
    assert labels == ["seed 0", "seed 1", "seed 5"]
    assert legend.legend_handles[-1].get_markerfacecolor() == "none"
    plt.close(fig)


def test_the_rule_line_is_at_by_step_on_the_rules_task_only(operators, unit_study_preset):
    """The operator study's rules read DCP: a dashed line at step 4 500 labelled "early: ≤
    4 500" on DCP, none on DBM; a study without rules has no line."""
    fig, _ = plot_onset_figure(operators, get_study("operators"), ["dcp", "dbm"], "paper")
    dcp, dbm = fig.axes[:2]
    (line,) = [line for line in dcp.lines if line.get_gid() == "rule"]
    assert list(line.get_xdata()) == [4500, 4500] and line.get_linestyle() == "--"
    assert "early: ≤ 4 500" in [t.get_text().strip() for t in dcp.texts]
    assert not [line for line in dbm.lines if line.get_gid() == "rule"]
    assert not [t for t in dbm.texts if "early" in t.get_text()]
    plt.close(fig)
    fig, drawn = plot_onset_figure(operators, unit_study_preset, ["dcp", "dbm"], "paper")
    assert drawn == 4  # Table I's Dist-GPRL seeds 0, 1 and NoCov seed 0 on DCP, seed 0 on DBM
    assert not [line for ax in fig.axes for line in ax.lines if line.get_gid() == "rule"]
    plt.close(fig)


def test_the_axis_spans_the_presets_run_length_per_task(operators, study_run):
    """The x range ends at the presets' run length on each task (DCP 30 000, DBM 45 000
    steps, distgprl/presets/paper.yaml), or at a later onset; the panel's title says it."""
    fig, _ = plot_onset_figure(operators, get_study("operators"), ["dcp", "dbm"], "paper")
    dcp, dbm = fig.axes[:2]
    assert dcp.get_xlim()[1] == pytest.approx(NEVER_BAND[1] * DCP_STEPS)
    assert dbm.get_xlim()[1] == pytest.approx(NEVER_BAND[1] * 45_000)
    assert "30 000 steps" in dcp.get_title() and "45 000 steps" in dbm.get_title()
    assert "first reaches 0.5 success (operators study, paper preset)" in fig._suptitle.get_text()
    plt.close(fig)
    study_run(operators, "paper", "dcp", "dist-gprl", 2, [0.0] * 21 + [0.6])  # onset 31 500
    fig, _ = plot_onset_figure(operators, get_study("operators"), ["dcp"], "paper")
    (dcp,) = fig.axes
    assert dcp.get_xlim()[1] == pytest.approx(NEVER_BAND[1] * 31_500)
    assert "31 500 steps" in dcp.get_title()
    plt.close(fig)


def test_regenerating_gives_the_same_bytes_and_nothing_to_draw_removes_the_files(operators):
    """The PNG and PDF are byte-identical when made twice from the same results; without a
    finished run of the study the figure's earlier files are removed, none written."""
    study = get_study("operators")
    out = operators / "out"

    def write(root, tasks):
        figure = plot_onset_figure(root, study, tasks, "paper")
        return write_or_remove_figure(figure, out / "onsets_operators_paper")

    written = write(operators, ["dcp", "dbm"])
    assert [p.name for p in written] == ["onsets_operators_paper.png", "onsets_operators_paper.pdf"]
    first = [p.read_bytes() for p in written]
    assert [p.read_bytes() for p in write(operators, ["dcp", "dbm"])] == first
    assert write(operators / "none", ["dcp"]) == []
    assert not any(out.iterdir())


def test_distgprl_curves_writes_every_studys_onset_figure(operators, unit_study_preset):
    """`write_curves` (``distgprl curves``) writes the onset figure of each study read beside
    the preset (here the operators and a second study beside ``paper``)."""
    from distgprl.report.curves import write_curves

    names = {p.name for p in write_curves(operators, "paper", operators / "out")}
    for study in ("operators", unit_study_preset.name):
        assert {f"onsets_{study}_paper.png", f"onsets_{study}_paper.pdf"} <= names
