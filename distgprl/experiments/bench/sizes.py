"""How much the benchmarks measure (`BenchSizes`: one preset per row of `SIZE_PRESETS`) and the
run they measure (`run_spec`: the paper preset, DCP / dist-gprl)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from distgprl.data import TASK_NAMES
from distgprl.identity import RunSpec

__all__ = [
    "BENCH_METHOD",
    "BENCH_TASK",
    "FULL_SIZES",
    "QUICK_SIZES",
    "SIZE_PRESETS",
    "TINY_SIZES",
    "BenchSizes",
    "run_spec",
    "sizes_for",
]

BENCH_TASK = "dcp"
BENCH_METHOD = "dist-gprl"


@dataclass(frozen=True)
class BenchSizes:
    """How much `run_benchmarks` measures (repeats, episodes, sweep points).

    Attributes:
        repeats: samples per adaptation micro-benchmark (each of ``inner`` calls).
        inner: calls per sample of the fast (microsecond) operations.
        naive_repeats: samples of the slow naive alternatives (PyBullet, GP re-solve).
        in_env_episodes: real environment episodes whose recorded adaptation time is reported.
        env_episodes: environment episodes per task of the env-step vs physics section.
        tasks: tasks of the env-step and the suite-cost sections.
        sac_repeats: samples of one SAC gradient step (regularised and plain, interleaved).
        learning_starts: random-action steps before the suite's timed training steps.
        suite_steps: timed training steps per (method, task) of the suite-cost section.
    """

    repeats: int
    inner: int
    naive_repeats: int
    in_env_episodes: int
    env_episodes: int
    tasks: tuple[str, ...]
    sac_repeats: int
    learning_starts: int
    suite_steps: int


#: The size presets, one column each: ``full`` (~10 min, `distgprl bench`), ``quick`` (~1 min,
#: ``--quick``) and ``tiny`` (the test suite's: every section runs, numbers are meaningless).
_PRESET_NAMES = ("full", "quick", "tiny")
_PRESET_TABLE: dict[str, tuple[Any, Any, Any]] = {
    #                  full                      quick              tiny
    "repeats":         (200,                     40,                5),
    "inner":           (10,                      5,                 2),
    "naive_repeats":   (40,                      8,                 2),
    "in_env_episodes": (30,                      5,                 1),
    "env_episodes":    (10,                      3,                 1),
    "tasks":           (TASK_NAMES,              TASK_NAMES,        TASK_NAMES[:1]),
    "sac_repeats":     (60,                      12,                2),
    "learning_starts": (60,                      20,                6),
    "suite_steps":     (150,                     30,                3),
}  # fmt: skip

SIZE_PRESETS: dict[str, BenchSizes] = {
    name: BenchSizes(**{field: row[column] for field, row in _PRESET_TABLE.items()})
    for column, name in enumerate(_PRESET_NAMES)
}
"""The presets by name (``full``, ``quick``, ``tiny``), built from the table above."""

FULL_SIZES = SIZE_PRESETS["full"]
QUICK_SIZES = SIZE_PRESETS["quick"]
TINY_SIZES = SIZE_PRESETS["tiny"]
"""The test-suite size: every section runs, numbers are meaningless."""


def sizes_for(quick: bool) -> BenchSizes:
    """The preset of ``distgprl bench``: `QUICK_SIZES` with ``--quick``, else `FULL_SIZES`."""
    return QUICK_SIZES if quick else FULL_SIZES


def run_spec(
    task: str = BENCH_TASK,
    method: str = BENCH_METHOD,
    env_overrides: dict[str, Any] | None = None,
    sac_overrides: dict[str, Any] | None = None,
) -> RunSpec:
    """The paper preset with the given overrides (a small replay buffer: allocation only)."""
    from distgprl.config import load_config
    from distgprl.methods import get_method

    overrides: dict[str, dict[str, Any]] = {"sac": {"buffer_size": 20_000, **(sac_overrides or {})}}
    if env_overrides:
        overrides["env"] = env_overrides
    return RunSpec(task, get_method(method), 0, load_config("paper", task, overrides))
