"""`distgprl fit` and `hap`: the GP via-point skill fitted to a demonstration and the
task's HAP safe subspace."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, cast

import typer

from distgprl.cli.common import (
    TASKS_HELP,
    TaskOption,
    user_errors,
)
from distgprl.errors import UserInputError


@user_errors
def fit(
    task: Annotated[
        str | None, typer.Option(metavar="TASK", help=f"Fit the task's shipped demo: {TASKS_HELP}.")
    ] = None,
    demo: Annotated[Path | None, typer.Option(help="Fit a demonstration CSV instead.")] = None,
    n_via_points: Annotated[int, typer.Option(min=2, help="Number of via-points N.")] = 15,
    out_dir: Annotated[Path, typer.Option(help="Output folder.")] = Path("results/skills"),
) -> None:
    """Fit the GP via-point skill to a demonstration; write JSON and a figure."""
    from distgprl.data import demo_path
    from distgprl.experiments.skills import fit_demonstration
    from distgprl.skill.gp import FitConfig

    if (task is None) == (demo is None):
        raise UserInputError("give exactly one of --task or --demo")
    source = demo_path(task) if task is not None else cast("Path", demo)  # one of them
    output = fit_demonstration(
        source, out_dir, name=task, config=FitConfig(n_via_points=n_via_points), task=task
    )
    worst = max(output.rmse["position"][:3])
    typer.echo(
        f"fitted {output.skill.name}: length scale {output.skill.kernel.length_scale:.4f}, "
        f"max position RMSE {worst * 1000:.3f} mm -> {output.json_path}, {output.figure_path}"
    )
    correlation = output.correlation
    windows = correlation["windows"]
    scales = ", ".join(
        f"{axis} {value:.3f} {'m' if axis in ('x', 'y', 'z') else 'rad'}"
        for axis, value in correlation["action_scale"].items()
    )
    typer.echo(f"action scale per unit raw action ({correlation['action_scale_rule']}): {scales}")
    typer.echo(
        f"Table I operator (lambda {correlation['correlation_lambda']:g}, K "
        f"{correlation['covariance_scale']!r}): neighbouring via-points correlate "
        f"{correlation['neighbour_correlation']:.2f} in the kernel; S_W eigenvalues "
        f"{min(w['eigenvalue_min'] for w in windows):.3f}-"
        f"{max(w['eigenvalue_max'] for w in windows):.3f}, largest off-diagonal "
        f"{max(w['max_off_diagonal'] for w in windows):.3f}"
    )
    for window in windows:
        spectrum = ", ".join(
            f"{axis} {a['eigenvalue_min']:.3f}-{a['eigenvalue_max']:.3f}"
            for axis, a in window["axes"].items()
        )
        typer.echo(f"  S_W via-points {window['via_points']}: {spectrum}")

    def reach_text(candidate: dict) -> str:
        low, high = candidate.get("reach_min", candidate["reach"]), candidate["reach"]
        return ", ".join(
            f"{axis} {1000 * low[axis]:.0f}-{1000 * high[axis]:.0f} "
            f"{'mm' if axis in ('x', 'y', 'z') else 'mrad'}"
            for axis in high
        )

    for scale, candidate in correlation["candidates"].items():
        if scale == "none":
            typer.echo(f"  no transform (S_W = I): one step's reach {reach_text(candidate)}")
            continue
        role = "Table I" if scale == correlation["covariance_scale"] else "study"
        role += " control" if scale == "signal-uncoupled" else ""
        typer.echo(
            f"  {role} operator K {scale!r}: S_W eigenvalues "
            f"{candidate['eigenvalue_min']:.3f}-{candidate['eigenvalue_max']:.3f}; "
            f"one step's reach per via-point {reach_text(candidate)}"
        )


@user_errors
def hap(
    task: TaskOption,
    out: Annotated[
        Path | None, typer.Option(help="Figure path (default results/hap/<task>.png).")
    ] = None,
) -> None:
    """Build (or load) the task's HAP safe subspace; report it and plot C_safe."""
    from distgprl.experiments.skills import plot_task_subspace

    out = out or Path("results/hap") / f"{task}.png"
    subspace, loaded = plot_task_subspace(task, out)
    stats = subspace.stats
    typer.echo(
        f"{task}: C_safe {len(subspace.unique_positions)} positions "
        f"({stats.n_mapped}/{stats.n_reachable} reachable poses mapped), "
        f"build {stats.build_seconds:.1f} s{' (cached)' if loaded else ''} -> {out}"
    )
