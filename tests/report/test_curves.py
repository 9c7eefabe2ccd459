"""Learning curves: the numbers plotted are the finished seeds' values on their common steps;
tables and figures are pure functions of the result files, whichever process makes them."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from distgprl.experiments.results import write_csv, write_json
from distgprl.experiments.runner import PROGRESS_FIELDS
from distgprl.report.curves import load_curves


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
    if finished:
        write_json(folder / "done.json", {"steps": steps[-1], "train_wall_time_s": 60.0})
    return folder


def test_curves_are_the_finished_seeds_on_their_common_steps(tmp_path):
    _run(tmp_path, "dist-gprl", 0, [0, 100, 200, 300], [0.0, 0.2, 0.4, 0.6])
    _run(tmp_path, "dist-gprl", 1, [0, 100, 300], [0.1, 0.5, 0.9])  # no curve point at 200
    _run(tmp_path, "dist-gprl", 2, [0, 100], [1.0, 1.0], finished=False)  # still training
    steps, values = load_curves(tmp_path, "p", "dcp", "dist-gprl")
    np.testing.assert_array_equal(steps, [0, 100, 300])
    np.testing.assert_allclose(values["success_rate"], [[0.0, 0.2, 0.6], [0.1, 0.5, 0.9]])
    np.testing.assert_allclose(values["success_rate"].mean(axis=0), [0.05, 0.35, 0.75])
    np.testing.assert_allclose(values["collision_rate"][1], [0.9, 0.5, 0.1])
    assert load_curves(tmp_path, "p", "dcp", "gprl-d") is None


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
