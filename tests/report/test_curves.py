"""Learning curves: the numbers plotted are the finished seeds' values on their common steps;
tables and figures are pure functions of the result files, whichever process makes them."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from distgprl.report.curves import common_curves, mean_and_band, plot_figure
from distgprl.report.frame import curve_frame
from distgprl.report.seed_curves import run_curves
from distgprl.schema import PROGRESS_FIELDS, write_csv, write_json

EPISODE = ("episode", "object_offset_x", "object_offset_y", "obstacle_offset_x")
EPISODE += ("obstacle_offset_y", "success", "collision")
"""Columns of the minimal evaluation.csv of a finished, evaluated run."""


def _run(root, method, seed, steps, success, finished=True, task="dcp"):
    folder = root / "p" / task / method / f"seed{seed}"
    rows = []
    for step, value in zip(steps, success, strict=True):
        row = dict.fromkeys(PROGRESS_FIELDS, "")
        row.update(
            step=step,
            episodes=step // 3,
            success_rate=value,
            collision_rate=1.0 - value,
            mean_return=10.0 * value,
            min_clearance_p5=0.01,
            wall_time_s=step / 10,
        )
        rows.append(row)
    write_csv(folder / "progress.csv", rows, PROGRESS_FIELDS)
    summary = {
        "success_rate": success[-1],
        "collision_rate": 1.0 - success[-1],
        "min_clearance_p5": 0.01,
        "mean_kinematic_retention": 0.5,
        "safe_success_rate": success[-1] / 2,
    }
    write_json(folder / "summary.json", {"summary": summary})
    write_csv(folder / "evaluation.csv", [{**dict.fromkeys(EPISODE, 0), "success": 1}], EPISODE)
    if finished:
        write_json(folder / "done.json", {"steps": steps[-1], "train_wall_time_s": 60.0})
    return folder


def test_curves_are_the_finished_seeds_on_their_common_steps(tmp_path):
    _run(tmp_path, "dist-gprl", 0, [0, 100, 200, 300], [0.0, 0.2, 0.4, 0.6])
    _run(tmp_path, "dist-gprl", 1, [0, 100, 300], [0.1, 0.5, 0.9])  # no curve point at 200
    _run(tmp_path, "dist-gprl", 2, [0, 100], [1.0, 1.0], finished=False)  # still training
    steps, values = common_curves(run_curves(curve_frame(tmp_path, "p"), "dcp", "dist-gprl"))
    np.testing.assert_array_equal(steps, [0, 100, 300])
    np.testing.assert_allclose(values["success_rate"], [[0.0, 0.2, 0.6], [0.1, 0.5, 0.9]])
    np.testing.assert_allclose(values["success_rate"].mean(axis=0), [0.05, 0.35, 0.75])
    np.testing.assert_allclose(values["collision_rate"][1], [0.9, 0.5, 0.1])
    assert common_curves(run_curves(curve_frame(tmp_path, "p"), "dcp", "gprl-d")) is None


@pytest.fixture
def results_tree(tmp_path):
    root = tmp_path / "results"
    for index, method in enumerate(("dist-gprl", "gprl-d", "dist-gprl-nocov")):
        for seed in (0, 1):
            shift = 0.1 * seed + 0.05 * index
            _run(root, method, seed, [0, 100, 200], [0.1, 0.3 + shift, 0.5 + shift])
    return root


def _make_figures(root, out, cwd, hash_seed):
    env = {**os.environ, "PYTHONHASHSEED": str(hash_seed), "MPLBACKEND": "Agg"}
    for command in ("tables", "curves"):
        subprocess.run(
            [sys.executable, "-m", "distgprl.cli", command, "--preset", "p"]
            + ["--root", str(root), "--out-dir", str(out)],
            cwd=cwd,
            env=env,
            check=True,
            capture_output=True,
        )
    return {path.name: path.read_bytes() for path in sorted(out.iterdir())}


def test_tables_and_figures_are_byte_identical_from_another_process(tmp_path, results_tree):
    """Another process, hash seed and working directory, with a checkpoint folder, a lock
    file and new file times in the tree: not a byte changes (nothing but the result files'
    contents is read)."""
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first = _make_figures(results_tree, tmp_path / "out_a", tmp_path / "a", 1)
    for folder in results_tree.glob("p/*/*/seed*"):
        (folder / "checkpoints").mkdir()
        (folder / "checkpoints" / "state.pkl").write_bytes(b"not a result")
        (folder / ".lock").write_text("")
        for path in folder.iterdir():
            os.utime(path, (1_000_000_000, 1_000_000_000))
    second = _make_figures(results_tree, tmp_path / "out_b", tmp_path / "b", 2)
    assert {"table1_p.csv", "hap_effect_p.pdf", "covariance_effect_p.png"} <= set(first)
    assert list(first) == list(second)
    for name, content in first.items():
        assert content == second[name], name


def test_curve_band_is_the_bootstrap_interval_of_the_mean_and_absent_for_one_seed():
    """The band is the 95 % percentile bootstrap interval of the mean over seeds: it lies
    within the seeds' range at every step, contains the mean, leaves at most 2.5 % (+ 1 %
    sampling slack) of the exact resample distribution (the 27 equally likely resamples of
    three seeds) on either side, is reproducible for one generator seed, and is absent for a
    single seed."""
    import itertools

    values = np.array([[0.0, 0.2, 0.6], [0.1, 0.5, 0.9], [0.2, 0.2, 0.3]])
    mean, band = mean_and_band(values, np.random.default_rng(0))
    np.testing.assert_allclose(mean, [0.1, 0.3, 0.6])
    low, high = band
    assert np.all(low <= mean) and np.all(mean <= high)
    assert np.all(low >= values.min(0) - 1e-12) and np.all(high <= values.max(0) + 1e-12)
    means = np.array([values[list(i)].mean(0) for i in itertools.product(range(3), repeat=3)])
    # the defining property of the percentile interval, on the exact resample distribution
    assert np.all((means < low - 1e-12).mean(0) <= 0.025 + 0.01)
    assert np.all((means > high + 1e-12).mean(0) <= 0.025 + 0.01)
    assert np.all(high - low > 0)
    again = mean_and_band(values, np.random.default_rng(0))[1]
    np.testing.assert_array_equal(again[0], low)
    mean, band = mean_and_band(values[:1], np.random.default_rng(0))
    np.testing.assert_array_equal(mean, values[0])
    assert band is None


def test_figure_band_is_the_bootstrap_interval_and_a_single_seed_has_no_band(tmp_path):
    """The filled band drawn around the mean curve spans the bootstrap interval of two
    seeds: with two seeds every resample mean is one seed's value or their average, so the
    band reaches from (nearly) the lower seed to (nearly) the upper one; a method with one
    seed has a curve but no band."""
    _run(tmp_path, "dist-gprl", 0, [0, 100], [0.2, 0.4])
    _run(tmp_path, "dist-gprl", 1, [0, 100], [0.4, 0.8])
    _run(tmp_path, "gprl-d", 0, [0, 100], [0.1, 0.3])
    fig, drawn = plot_figure(tmp_path, "p", ["dcp"], ("dist-gprl", "gprl-d"), "t")
    assert drawn == 2
    success = fig.axes[0]
    assert len(success.lines) == 2 and len(success.collections) == 1  # gprl-d: no band
    vertices = success.collections[0].get_paths()[0].vertices
    # P(both resamples the lower seed) = 1/4 > 2.5 %: the percentiles are the seeds' values
    assert vertices[:, 1].max() == pytest.approx(0.8)
    assert vertices[:, 1].min() == pytest.approx(0.2)
    import matplotlib.pyplot as plt

    plt.close(fig)


@pytest.mark.parametrize("preset", ["p", "nonexistent"])
def test_curves_without_results_is_a_clear_user_error_naming_the_folder(tmp_path, preset):
    """No results under <root>/<preset> (wrong --preset or --root) is a UserInputError
    naming the folder searched, not matplotlib's "Number of rows must be a positive
    integer"; the CLI prints it as one line with exit code 2."""
    from distgprl.errors import UserInputError
    from distgprl.report.curves import write_curves

    (tmp_path / "p").mkdir()  # the preset folder exists but holds no task
    with pytest.raises(UserInputError, match=f"{tmp_path / preset}: no results"):
        write_curves(tmp_path, preset, tmp_path / "out")
    result = subprocess.run(
        [sys.executable, "-m", "distgprl.cli", "curves", "--preset", preset]
        + ["--root", str(tmp_path), "--out-dir", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        env={**os.environ, "MPLBACKEND": "Agg"},
    )
    assert result.returncode == 2
    assert "Traceback" not in result.stderr and str(tmp_path / preset) in result.stderr


def test_a_figure_without_any_finished_run_is_removed_not_left_stale(tmp_path):
    """When no method of a figure has a finished run any more (say, its runs were archived
    for a re-run), `write_curves` removes the figure's earlier files instead of leaving them."""
    from distgprl.report.curves import write_curves

    _run(tmp_path, "gprl", 0, [0, 100], [0.1, 0.3])
    out = tmp_path / "figures"
    out.mkdir()
    for suffix in ("png", "pdf"):
        (out / f"hap_effect_p.{suffix}").write_bytes(b"an old figure")
    written = write_curves(tmp_path, "p", out)
    assert not (out / "hap_effect_p.png").exists() and not (out / "hap_effect_p.pdf").exists()
    assert out / "all_methods_p.png" in written


def test_rate_bands_stay_in_the_unit_interval_and_returns_are_not_limited(tmp_path):
    """Seeds at 0.9 and 1.0 (and 0.7, 0.8): the success band (means of resampled seeds) reaches
    1 and never passes it, the collision band stays at 0, the return band reaches the upper
    seed's return (10 x success, no [0, 1] limit); rate axes span [0, 1]."""
    _run(tmp_path, "dist-gprl", 0, [0, 100], [0.9, 1.0])
    _run(tmp_path, "dist-gprl", 1, [0, 100], [0.7, 0.8])
    fig, _ = plot_figure(tmp_path, "p", ["dcp"], ("dist-gprl",), "t")
    success, collision, returns = fig.axes
    high = [ax.collections[0].get_paths()[0].vertices[:, 1] for ax in fig.axes]
    assert high[0].max() == pytest.approx(1.0) and high[0].min() >= 0.0
    assert high[1].min() == pytest.approx(0.0) and high[1].max() <= 1.0
    assert high[2].max() == pytest.approx(10.0)
    assert all(ax.get_ylim() == pytest.approx((-0.03, 1.03)) for ax in (success, collision))
    import matplotlib.pyplot as plt

    plt.close(fig)


def test_one_legend_outside_the_panels_labels_on_every_axis_and_ours_on_top(tmp_path):
    """Every panel has a y-axis label; the figure has one legend (none per panel) that
    overlaps no panel; Dist-GPRL's lines are the widest and drawn above the others."""
    for method in ("dist-gprl", "gprl-d", "dist-gprl-nocov"):
        for task in ("dcp", "dbm"):
            _run(tmp_path, method, 0, [0, 100], [0.2, 0.6], task=task)
    fig, drawn = plot_figure(
        tmp_path, "p", ["dcp", "dbm"], ("gprl-d", "dist-gprl", "dist-gprl-nocov"), "t"
    )
    assert drawn == 6
    assert all(ax.get_ylabel() for ax in fig.axes)
    assert not [ax for ax in fig.axes if ax.get_legend() is not None]
    assert len(fig.legends) == 1
    fig.canvas.draw()
    legend = fig.legends[0].get_window_extent()
    for ax in fig.axes:
        assert not legend.overlaps(ax.get_tightbbox())
    labels = [text.get_text() for text in fig.legends[0].get_texts()]
    assert labels == ["GPRL-D (1 seed)", "Dist-GPRL (ours) (1 seed)", "Dist-GPRL-NoCov (1 seed)"]
    for ax in fig.axes:
        ours, *others = sorted(ax.lines, key=lambda line: line.get_zorder(), reverse=True)
        assert ours.get_linewidth() > max(line.get_linewidth() for line in others)
        assert ours.get_color() == "black"
    import matplotlib.pyplot as plt

    plt.close(fig)


def test_figures_are_a_vector_pdf_and_a_150_dpi_png(tmp_path):
    from PIL import Image

    from distgprl.report.curves import write_curves

    _run(tmp_path, "dist-gprl", 0, [0, 100], [0.2, 0.6])
    written = write_curves(tmp_path, "p", tmp_path / "out")
    png = tmp_path / "out" / "hap_effect_p.png"
    assert png in written and (tmp_path / "out" / "hap_effect_p.pdf") in written
    with Image.open(png) as image:
        assert image.size == (12 * 150, round(3.2 * 150))
    assert (tmp_path / "out" / "hap_effect_p.pdf").read_bytes().startswith(b"%PDF")


# --- a study's learning curves, seed by seed (`plot_reading_curves`) ---


def test_run_curves_keep_each_seed_on_its_own_steps(tmp_path):
    _run(tmp_path, "dist-gprl", 0, [0, 100, 200], [0.0, 0.2, 0.4])
    _run(tmp_path, "dist-gprl", 3, [0, 100], [0.1, 0.5])
    _run(tmp_path, "dist-gprl", 1, [0, 100], [1.0, 1.0], finished=False)  # still training
    curves = run_curves(curve_frame(tmp_path, "p"), "dcp", "dist-gprl")
    assert list(curves) == [0, 3]
    np.testing.assert_array_equal(curves[3][0], [0, 100])
    np.testing.assert_allclose(curves[0][1]["success_rate"], [0.0, 0.2, 0.4])


def test_a_studys_curves_show_every_seed_of_every_reading_and_the_mean(study_tree):
    """One panel per reading (Table I's first) and NoCov's for the operator study; a line
    per finished seed plus the mean where there are several; a reading without runs says so."""
    from distgprl.report.curves import plot_reading_curves
    from distgprl.report.seed_curves import reading_columns
    from distgprl.studies import get_study

    study = get_study("operators")
    columns = reading_columns(study)
    assert [c[0] for c in columns] == ["paper", *study.presets, "paper"]
    assert [c[1] for c in columns] == ["dist-gprl"] * 5 + ["dist-gprl-nocov"]
    fig, drawn = plot_reading_curves(study_tree, study, ["dcp"])
    assert drawn == 3  # Table I's, the signal reading's and NoCov's panels
    axes = fig.axes[: len(columns)]
    table1, unit, signal, _, control, nocov = axes
    assert len(table1.get_lines()) == 3  # two seeds and their mean
    np.testing.assert_allclose(table1.get_lines()[-1].get_ydata(), [0.2, 0.0, 0.0, 0.4])
    assert len(signal.get_lines()) == 1 and len(nocov.get_lines()) == 1  # one seed: no mean
    assert not unit.get_lines() and "no finished runs" in [t.get_text() for t in unit.texts]
    assert "(control)" in control.get_title() and not control.get_lines()
    assert "operator-signal, 1 seed" in signal.get_title()


def test_a_studys_curves_leave_out_seeds_beyond_its_own(study_tree, study_run):
    """A reading's runs at seeds a rule alone reads (5-9; `Study.seeds` is 0-4) are not
    drawn: the signal panel keeps its one seed."""
    from distgprl.report.curves import plot_reading_curves
    from distgprl.studies import get_study

    for seed in range(5, 10):
        study_run(study_tree, "operator-signal", "dcp", "dist-gprl", seed, [0.0, 0.9])
    fig, _ = plot_reading_curves(study_tree, get_study("operators"), ["dcp"])
    signal = fig.axes[2]
    assert "operator-signal, 1 seed" in signal.get_title()
    assert len(signal.get_lines()) == 1


def test_write_curves_writes_each_studys_curves_and_removes_them_without_runs(
    study_tree, unit_study_preset
):
    import shutil

    from distgprl.report.curves import write_curves

    out = study_tree / "out"
    names = {p.name for p in write_curves(study_tree, "paper", out)}
    assert {"curves_operators_paper.png", "curves_operators_paper.pdf"} <= names
    assert {"curves_unit_paper.png", "curves_unit_paper.pdf"} <= names
    for preset in ("paper", "operator-signal"):
        shutil.rmtree(study_tree / preset / "dcp")
    (study_tree / "paper" / "dbm" / "gprl" / "seed0").mkdir(parents=True)  # a task folder
    names = {p.name for p in write_curves(study_tree, "paper", out)}
    assert not any(name.startswith("curves_") for name in names)
    assert not (out / "curves_operators_paper.png").exists()
