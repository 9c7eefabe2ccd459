"""The benchmark package (the paper's §V figures): `run_benchmarks` at the tiny size runs every
section and writes a well-formed JSON + figure; the size presets are one table; the package's
modules stay small and its entry point (``python -m distgprl.experiments.bench``) works.

No timing thresholds: only structure, and that every number is positive and finite.
"""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import asdict, fields

import numpy as np
import pytest
import torch

from distgprl.agents.numpy_actor import NumpyActor
from distgprl.experiments.bench.markdown import markdown_table
from distgprl.experiments.bench.run import run_benchmarks
from distgprl.experiments.bench.sizes import (
    FULL_SIZES,
    QUICK_SIZES,
    SIZE_PRESETS,
    TINY_SIZES,
    BenchSizes,
    sizes_for,
)
from distgprl.experiments.bench.suite import suite_cpu_hours
from distgprl.experiments.bench.timing import Timing, measure, measure_interleaved
from distgprl.schema import read_json


def _numbers(node, path=""):
    """(path, value) of every int/float leaf of a JSON document."""
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _numbers(value, f"{path}.{key}")
    elif isinstance(node, list):
        for index, value in enumerate(node):
            yield from _numbers(value, f"{path}[{index}]")
    elif isinstance(node, int | float) and not isinstance(node, bool):
        yield path, node


def test_measure_and_timing():
    timing = measure(lambda: sum(range(10)), repeats=5, warmup=1, inner=2)
    assert 0 < timing.p10_us <= timing.median_us <= timing.p90_us
    assert Timing.from_samples([1e-3, 2e-3, 3e-3]).median_us == pytest.approx(2000.0)
    paired = measure_interleaved({"a": lambda: None, "b": lambda: None}, repeats=3)
    assert set(paired) == {"a", "b"}


def test_numpy_actor_matches_torch_actor():
    from gymnasium import spaces
    from stable_baselines3.common.torch_layers import FlattenExtractor
    from stable_baselines3.sac.policies import Actor

    observation = spaces.Box(-1, 1, (12,), np.float32)
    action = spaces.Box(-1, 1, (4,), np.float32)
    actor = Actor(observation, action, [32, 32], FlattenExtractor(observation), 12)
    state = np.random.default_rng(0).normal(size=(5, 12)).astype(np.float32)
    with torch.no_grad():
        expected = actor(torch.as_tensor(state), deterministic=True).numpy()
    np.testing.assert_allclose(NumpyActor(actor)(state), expected, atol=1e-5)


def test_run_benchmarks_tiny(tmp_path):
    path = run_benchmarks(True, tmp_path, sizes=TINY_SIZES)
    assert path.exists() and path.with_suffix(".png").stat().st_size > 0
    document = read_json(path)
    assert set(document) - {"meta"} == {
        "quick", "sizes", "machine", "load_average_after", "wall_time_s", "adaptation",
        "environment", "sac_step", "ratios", "suite",
    }  # fmt: skip
    assert set(document["ratios"]) == {
        "regularised_over_plain_sac_step", "env_step_over_bare_physics", "suite_over_floor",
    }  # fmt: skip
    # The headline ratio is the CPU-time one of the SAC step section, measured interleaved.
    sac = document["sac_step"]
    assert document["ratios"]["regularised_over_plain_sac_step"] == pytest.approx(
        sac["cpu_regularised"]["median_us"] / sac["cpu_plain"]["median_us"]
    )
    adaptation = document["adaptation"]
    assert set(adaptation["per_window"]) == {"edf", "gp_conditioning", "policy", "total"}
    assert set(adaptation["naive_per_window"]) >= {"edf_pybullet", "gp_resolve"}
    # Issue 29's headline keys: env step over the physics in it, the suite's cost.
    for task in TINY_SIZES.tasks:
        environment = document["environment"][task]
        assert document["ratios"]["env_step_over_bare_physics"][task] == pytest.approx(
            environment["env_step_per_episode"]["median_us"]
            / environment["bare_physics_per_episode"]["median_us"]
        )
        assert document["ratios"]["env_step_over_bare_physics"][task] > 1.0
    suite = document["suite"]
    assert len(suite["methods"]) == 7 and "demo" not in suite["methods"]
    assert suite["hours_two_idle_cores"] == pytest.approx(suite["cpu_hours"] / 2)
    # The floor: the products of a plain update and the bare physics of section 2b.
    floor = suite["floor"]
    assert floor["hours_idle_cores"] == pytest.approx(floor["cpu_hours"] / 2)
    assert set(floor["physics_cpu_ms_per_step"]) == set(TINY_SIZES.tasks)
    for task in TINY_SIZES.tasks:
        assert (
            floor["physics_cpu_ms_per_step"][task]
            == document["environment"][task]["bare_physics_cpu_ms"]
        )
    assert floor["sac_update"]["calls_per_update"] == 49
    assert 0 < floor["sac_update"]["matrix_product_share"] < 1
    # Issue 49's keys: the suite over its floor, the update's framework work beside its products.
    assert document["ratios"]["suite_over_floor"] == pytest.approx(
        suite["cpu_hours"] / floor["cpu_hours"]
    )
    update = floor["sac_update"]
    assert update["non_product_ms"] == pytest.approx(
        update["update_ms"] - update["matrix_products_ms"]
    )
    agreements = ("edf_pybullet_max_abs_difference_m", "policy_numpy_vs_torch_max_abs_difference")
    names = {where.rsplit(".", 1)[-1] for where, _ in _numbers(document)}
    assert set(agreements) <= names  # the agreement checks below are not skipped silently
    for where, value in _numbers({k: v for k, v in document.items() if k != "meta"}):
        assert math.isfinite(value), where
        if where.rsplit(".", 1)[-1] in agreements:
            assert 0 <= value < 1e-3, where  # agreement with PyBullet / torch, not a timing
        elif "load_average" in where:
            continue  # an idle load can be 0
        else:
            assert value > 0, where
    table = markdown_table(document)
    assert table.count("|") > 40 and "per episode" in table and "its floor" in table
    assert "env step" in table and "SAC gradient step" in table
    assert "over its floor" in table and "framework work" in table


def test_suite_cpu_hours_is_seeds_times_steps_times_cost():
    """`suite_cpu_hours` at a size checkable by hand: 2 methods x 2 tasks x 3 seeds, 10 and 20
    steps per run, per-step costs 1-4 s: (10 (1 + 3) + 20 (2 + 4)) x 3 s = 480 s."""
    costs = {("a", "dcp"): 1.0, ("a", "dbm"): 2.0, ("b", "dcp"): 3.0, ("b", "dbm"): 4.0}
    hours = suite_cpu_hours(costs, {"dcp": 10, "dbm": 20}, seeds=3)
    assert hours == pytest.approx(480.0 / 3600.0)
    assert suite_cpu_hours({}, {"dcp": 10}, seeds=5) == 0.0


def test_size_presets_are_one_table():
    """Every preset is a `BenchSizes` with every field set from the table; the named constants
    and ``sizes_for`` are the table's rows, and each preset measures no more than the next
    larger one (tiny <= quick <= full, field by field)."""
    assert set(SIZE_PRESETS) == {"full", "quick", "tiny"}
    assert SIZE_PRESETS["full"] is FULL_SIZES is sizes_for(False)
    assert SIZE_PRESETS["quick"] is QUICK_SIZES is sizes_for(True)
    assert SIZE_PRESETS["tiny"] is TINY_SIZES
    for small, large in (
        (TINY_SIZES, QUICK_SIZES),
        (QUICK_SIZES, FULL_SIZES),
    ):
        for field in fields(BenchSizes):
            a, b = getattr(small, field.name), getattr(large, field.name)
            if isinstance(a, tuple):
                assert 0 < len(a) <= len(b), field.name
            else:
                assert 0 < a <= b, field.name
    assert asdict(FULL_SIZES)["suite_steps"] == 150


def test_module_entry_point_parses_its_arguments():
    """``python -m distgprl.experiments.bench`` is the package's argparse main."""
    result = subprocess.run(
        [sys.executable, "-m", "distgprl.experiments.bench", "--help"],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    assert "--quick" in result.stdout and "--out" in result.stdout
