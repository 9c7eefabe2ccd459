"""`distgprl fit` and `hap`: show a task's committed GP skill (or fit a demonstration
explicitly) and write its result files; build (or load) a task's HAP safe subspace and plot
it."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from distgprl.config_types import EnvConfig
from distgprl.io import atomic_write_bytes
from distgprl.schema import read_json, write_json
from distgprl.skill.committed import CommittedSkill, read_skill_file
from distgprl.skill.demos import Demonstration, load_demonstration
from distgprl.skill.gp import FitConfig, GPSkill, fit_skill, reconstruction_error

if TYPE_CHECKING:
    from distgprl.safety.hap_build import SafeSubspace

AXES = ("x", "y", "z", "rx", "ry", "rz")


@dataclass(frozen=True)
class FitOutput:
    """Where `fit_demonstration` / `show_committed_skill` wrote their files, and the skill."""

    skill: GPSkill
    json_path: Path
    figure_path: Path
    rmse: dict[str, list[float]]
    correlation: dict
    committed: CommittedSkill | None = None
    """The committed skill file shown (None for a fresh fit)."""


def correlation_summary(
    skill: GPSkill, env_config: EnvConfig | None = None, tc_range: np.ndarray | None = None
) -> dict:
    """How strongly the covariance transform acts on this skill's windows.

    Builds the windows' S_W exactly as the adaptation env does (Eq. transformed_action,
    ``build_action_layout`` for ``dist-gprl``): one (L, L) operator per window and axis. Reports,
    per window: the eigenvalue range of S_W over its axes (its shrink of a raw action along its
    eigenvectors; 1 = unchanged), the largest off-diagonal entry (how much a via-point's raw
    action moves its neighbours) and the same per axis. Also the kernel's correlation between
    neighbouring via-points, k(spacing) / k(0), and the same spectrum under every scale of K
    of `distgprl.adaptation.layout.COVARIANCE_SCALES` (``candidates``: ``"zero-mean"``, Table
    I's; ``"signal"`` — the GP's covariance in via-point units; ``"unit"`` — the
    unit-variance correlation matrix; ``"correlation"`` and ``"signal-uncoupled"``), so
    `distgprl fit` shows them side by side. When every eigenvalue is near 1 and the
    off-diagonals near 0, S_W is nearly the identity: the transform then barely correlates
    the update (docs/findings/operator.md).

    The *reach* of an axis is the largest displacement one step's action can give one
    via-point along it: every raw action entry saturated at +-1 with the signs of S_W's row,
    max_i sum_j |S_W[i, j]| times the action's scale on that axis (m for x, y, z; rad for
    rx, ry, rz). Without the transform (``dist-gprl-nocov``) it is the action scale itself;
    a via-point shared by two windows can move by the sum of both. ``reach_min`` is the
    smallest reach over the window via-points: the reach rule's action scales
    (``action_scale_rule="reach"``, needing the task's ``tc_range`` (3,), m) make it
    max(TC range, minimum reach) on every axis under the Table I operator; without a
    ``tc_range`` the summary uses the configured fixed scales (``action_scale_rule``
    ``"fixed"``) and says so.

    Returns:
        A JSON-ready dict: ``correlation_lambda``, ``covariance_scale``, ``length_scale`` (of K:
        the fitted one unless ``env_config.correlation_length_scale`` sets it),
        ``via_point_spacing`` (normalised time), ``neighbour_correlation``, ``windows``: one dict
        per window with ``via_points`` (indices), ``eigenvalue_min``, ``eigenvalue_max``,
        ``max_off_diagonal`` and ``axes`` (the same three, ``reach`` and ``reach_min``, per
        axis x..rz), ``action_scale_rule`` and ``action_scale`` (per axis), ``reach`` and
        ``reach_min``: per axis, the largest reach and the smallest ``reach_min`` over the
        windows, and ``candidates``: per scale, ``eigenvalue_min`` / ``eigenvalue_max`` over
        all windows and axes and ``reach`` and ``reach_min`` per axis (absent for a scale the
        skill cannot build, e.g. ``"signal"`` without its axis scale), and ``"none"`` (no
        transform: S_W = I) with its ``reach``.
    """
    from distgprl.adaptation.layout import COVARIANCE_SCALES, build_action_layout
    from distgprl.methods import get_method

    env_config = env_config or EnvConfig()
    if tc_range is None and env_config.action_scale_rule == "reach":
        env_config = dataclasses.replace(env_config, action_scale_rule="fixed")
    spacing = float(np.min(np.diff(skill.via_times)))
    length_scale = float(env_config.correlation_length_scale or skill.kernel.length_scale)
    method = get_method("dist-gprl")

    def describe(config: EnvConfig) -> list[dict]:
        layout = build_action_layout(skill, config, method, tc_range=tc_range)
        windows = []
        for indices, operators in zip(layout.indices, layout.operators, strict=True):
            axes = {}
            for axis, operator, scale in zip(AXES, operators, layout.scale, strict=True):
                eigenvalues = np.linalg.eigvalsh(0.5 * (operator + operator.T))
                off_diagonal = operator - np.diag(np.diag(operator))
                axes[axis] = {
                    "eigenvalue_min": float(eigenvalues.min()),
                    "eigenvalue_max": float(eigenvalues.max()),
                    "max_off_diagonal": float(np.abs(off_diagonal).max()),
                    "reach": float(np.abs(operator).sum(axis=1).max() * scale),
                    "reach_min": float(np.abs(operator).sum(axis=1).min() * scale),
                }
            windows.append(
                {
                    "via_points": [int(i) for i in indices],
                    "eigenvalue_min": min(a["eigenvalue_min"] for a in axes.values()),
                    "eigenvalue_max": max(a["eigenvalue_max"] for a in axes.values()),
                    "max_off_diagonal": max(a["max_off_diagonal"] for a in axes.values()),
                    "axes": axes,
                }
            )
        return windows

    chosen = describe(env_config)  # raises for a scale the skill cannot build
    candidates = {}
    for scale in COVARIANCE_SCALES:
        if scale == env_config.covariance_scale:
            windows = chosen
        else:
            try:
                windows = describe(dataclasses.replace(env_config, covariance_scale=scale))
            except ValueError:  # e.g. a skill saved without its axis scale
                continue
        candidates[scale] = {
            "eigenvalue_min": min(w["eigenvalue_min"] for w in windows),
            "eigenvalue_max": max(w["eigenvalue_max"] for w in windows),
            "reach": largest_reach(windows),
            "reach_min": smallest_reach(windows),
        }
    raw_scale = build_action_layout(
        skill, env_config, get_method("dist-gprl-nocov"), tc_range=tc_range
    ).scale
    candidates["none"] = {"reach": dict(zip(AXES, (float(v) for v in raw_scale), strict=True))}
    return {
        "correlation_lambda": float(env_config.correlation_lambda),
        "covariance_scale": env_config.covariance_scale,
        "length_scale": length_scale,
        "via_point_spacing": spacing,
        "neighbour_correlation": float(np.exp(-(spacing**2) / (2 * length_scale**2))),
        "action_scale_rule": env_config.action_scale_rule,
        "action_scale": dict(zip(AXES, (float(v) for v in raw_scale), strict=True)),
        "windows": chosen,
        "reach": largest_reach(chosen),
        "reach_min": smallest_reach(chosen),
        "candidates": candidates,
    }


def largest_reach(windows: list[dict]) -> dict[str, float]:
    """Per axis, the largest ``reach`` over `correlation_summary`'s ``windows``."""
    return {axis: max(w["axes"][axis]["reach"] for w in windows) for axis in AXES}


def smallest_reach(windows: list[dict]) -> dict[str, float]:
    """Per axis, the smallest ``reach_min`` over `correlation_summary`'s ``windows``."""
    return {axis: min(w["axes"][axis]["reach_min"] for w in windows) for axis in AXES}


def fit_demonstration(
    demo_file: str | Path,
    out_dir: str | Path = "results/skills",
    name: str | None = None,
    config: FitConfig | None = None,
    task: str | None = None,
) -> FitOutput:
    """Fit a skill to a demonstration CSV on this machine (explicitly: environments read the
    committed skills, `show_committed_skill`); write ``<name>.json`` and ``<name>.png``.

    The demonstration is validated first (a `UserInputError` leaves nothing written).
    ``task`` (the demonstration's task, if it has one) gives the TC range from which the
    action scales and reach are reported (`correlation_summary`).
    """
    config = config or FitConfig()
    demo = load_demonstration(demo_file, min_rows=config.n_via_points)
    name = name or demo.name
    skill = dataclasses.replace(fit_skill(demo, config), name=name)
    return write_skill_report(skill, demo, demo_file, out_dir, name, config, task)


def show_committed_skill(
    task: str,
    out_dir: str | Path = "results/skills",
    n_via_points: int = 15,
    skills_dir: str | Path | None = None,
) -> FitOutput:
    """The task's committed skill (`distgprl.skill.committed`; nothing is fitted): its
    reconstruction error, operator summary and figure, written to ``out_dir`` as
    `fit_demonstration` writes a fresh fit's."""
    from distgprl.data import demo_path
    from distgprl.skill.committed import committed_skill_path, load_committed_skill

    skill = load_committed_skill(task, n_via_points, skills_dir)
    committed = read_skill_file(committed_skill_path(task, skills_dir))
    demo = load_demonstration(demo_path(task), min_rows=n_via_points)
    output = write_skill_report(
        skill, demo, demo_path(task), out_dir, task, committed.fit_config, task, committed
    )
    return output


def write_skill_report(
    skill: GPSkill,
    demo: Demonstration,
    demo_file: str | Path,
    out_dir: str | Path,
    name: str,
    config: FitConfig,
    task: str | None,
    committed: CommittedSkill | None = None,
) -> FitOutput:
    """Write ``<name>.json`` (skill, RMSE against ``demo``, operator summary and, for a
    committed skill, its file and provenance) and ``<name>.png`` into ``out_dir``."""
    rmse = reconstruction_error(skill, demo)
    correlation = correlation_summary(skill, tc_range=task_tc_range(task))
    out_dir = Path(out_dir)
    figure_path = plot_fit(skill, demo, out_dir / f"{name}.png")
    source = (
        {}
        if committed is None
        else {"committed_skill": {"file": str(committed.path), **committed.provenance}}
    )
    json_path = write_json(
        out_dir / f"{name}.json",
        {
            "skill": skill.to_dict(),
            **source,
            "demonstration": {
                "file": str(demo_file),
                "sha256": demo.sha256,
                "samples": int(demo.times.shape[0]),
            },
            "rmse": {"axes": list(AXES), **rmse},
            "correlation_operator": correlation,
            "figure": figure_path.name,
        },
        kind="skill",
        fit_config=config.__dict__,
    )
    return FitOutput(skill, json_path, figure_path, rmse, correlation, committed)


def task_tc_range(task: str | None) -> np.ndarray | None:
    """The task's TC range (3,), m, or None without a task."""
    if task is None:
        return None
    from distgprl.sim.tasks import get_task

    return np.asarray(get_task(task).tc_range)


def fresh_fit_differences(committed: GPSkill, fresh: GPSkill, task: str) -> dict[str, float]:
    """How a fresh fit on this machine differs from the committed skill: the largest
    relative difference of the shared kernel's, the axis kernels' parameters, the action
    scales and the Table I operator's reach, and the largest absolute one of the via-points
    (m, rad); 0.0 where they agree bit for bit."""

    def relative(first: object, second: object) -> float:
        a, b = np.asarray(first, dtype=float), np.asarray(second, dtype=float)
        scale = np.maximum(np.abs(a), np.abs(b))
        return float(np.max(np.where(scale > 0, np.abs(a - b) / np.where(scale > 0, scale, 1), 0)))

    def kernel_values(skill: GPSkill) -> np.ndarray:
        kernels = (skill.kernel, *(skill.axis_kernels or ()))
        return np.array([[k.length_scale, k.signal_variance, k.noise_variance] for k in kernels])

    tc_range = task_tc_range(task)
    summaries = [correlation_summary(s, tc_range=tc_range) for s in (committed, fresh)]
    old, new = kernel_values(committed), kernel_values(fresh)
    return {
        "kernel": relative(old[0], new[0]),
        "axis_kernels": relative(old[1:], new[1:]),
        "via_points": float(np.max(np.abs(committed.via_points - fresh.via_points))),
        "action_scale": relative(
            list(summaries[0]["action_scale"].values()), list(summaries[1]["action_scale"].values())
        ),
        "reach": relative(
            list(summaries[0]["reach"].values()), list(summaries[1]["reach"].values())
        ),
    }


def load_skill(path: str | Path) -> GPSkill:
    """Load a skill written by `fit_demonstration`."""
    return GPSkill.from_dict(read_json(path)["skill"])


def plot_fit(skill: GPSkill, demo: Demonstration, out_path: str | Path) -> Path:
    """Figure: demonstration vs GP for position, velocity and acceleration per axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tau = demo.normalised_times
    t = demo.times - demo.times[0]
    gp = [
        skill.position(skill.via_points, tau),
        skill.velocity(skill.via_points, tau),
        skill.acceleration(skill.via_points, tau),
    ]
    demo_velocity = np.gradient(demo.poses, demo.times, axis=0)
    reference = [demo.poses, demo_velocity, np.gradient(demo_velocity, demo.times, axis=0)]
    rows = ("position", "velocity", "acceleration")
    units = (("m", "rad"), ("m/s", "rad/s"), ("m/s²", "rad/s²"))
    fig, axes = plt.subplots(3, 6, figsize=(18, 8), sharex=True)
    for r, row in enumerate(rows):
        for a, axis_name in enumerate(AXES):
            ax = axes[r, a]
            ax.plot(t, reference[r][:, a], color="0.6", lw=2.5, label="demonstration")
            ax.plot(t, gp[r][:, a], color="C0", lw=1.2, label="GP skill")
            if r == 0:
                ax.plot(
                    skill.via_times * skill.duration,
                    skill.via_points[:, a],
                    "o",
                    color="C3",
                    ms=3,
                    label="via-points",
                )
                ax.set_title(axis_name)
            if a == 0:
                ax.set_ylabel(f"{row} [{units[r][0]}]")
            elif a == 3:
                ax.set_ylabel(f"[{units[r][1]}]")
            if r == 2:
                ax.set_xlabel("t [s]")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"GP skill '{skill.name}': l = {skill.kernel.length_scale:.3f} (normalised time)")
    fig.tight_layout()
    import io

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=80)
    plt.close(fig)
    return atomic_write_bytes(out_path, buffer.getvalue())


def plot_task_subspace(task: str, out_path: str | Path) -> tuple[SafeSubspace, bool]:
    """Build (or load from the cache) the task's HAP safe subspace and write its C_safe
    figure with all the task's obstacles, static and dynamic (`distgprl hap`).

    Returns:
        The subspace, and True if it was loaded from the cache rather than built.
    """
    from distgprl.data import check_task_name
    from distgprl.envs.tasks import load_task_subspace
    from distgprl.safety.hap_plot import plot_subspace
    from distgprl.sim.tasks import get_task

    check_task_name(task)
    subspace, loaded = load_task_subspace(task)
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    sim = get_task(task).make_sim()
    try:
        plot_subspace(subspace, sim.obstacle_shapes(), out_path, title=f"{task.upper()} C_safe")
    finally:
        sim.close()
    return subspace, loaded
