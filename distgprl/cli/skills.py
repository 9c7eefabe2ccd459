"""`distgprl fit` and `hap`: the task's committed GP via-point skill (refitted only by
``fit --write``; a demonstration CSV fitted on request) and the task's HAP safe subspace."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, cast

import typer

from distgprl.cli.common import (
    TASKS_HELP,
    TaskOption,
    given_options,
    user_errors,
)
from distgprl.errors import UserInputError

if TYPE_CHECKING:
    from distgprl.skill.committed import CommittedSkill
    from distgprl.skill.gp import GPSkill


@user_errors
def fit(
    ctx: typer.Context,
    task: Annotated[
        str | None,
        typer.Option(metavar="TASK", help=f"Show the task's committed skill: {TASKS_HELP}."),
    ] = None,
    demo: Annotated[Path | None, typer.Option(help="Fit a demonstration CSV instead.")] = None,
    n_via_points: Annotated[int, typer.Option(min=2, help="Number of via-points N.")] = 15,
    out_dir: Annotated[Path, typer.Option(help="Output folder.")] = Path("results/skills"),
    write: Annotated[
        bool,
        typer.Option(
            "--write",
            help="Refit the task's shipped demonstration on this machine and write its "
            "committed skill file (every task without --task).",
        ),
    ] = False,
    compare: Annotated[
        bool, typer.Option("--compare", help="Also show how a fresh fit on this machine differs.")
    ] = False,
    skills_dir: Annotated[
        Path | None,
        typer.Option(help="Folder of the committed skill files (default: the package's)."),
    ] = None,
) -> None:
    """Show a task's committed GP skill (or fit a demonstration); write JSON and a figure.

    Environments read the committed skills (distgprl/data/skills/<task>.json); only --write
    refits them."""
    from distgprl.data import TASK_NAMES, check_task_name
    from distgprl.experiments.skills import fit_demonstration, show_committed_skill
    from distgprl.skill.gp import FitConfig

    if write:
        if demo is not None:
            raise UserInputError("--write refits a task's committed skill: give --task, not --demo")
        unread = given_options(ctx, "out_dir", "compare")
        if unread:
            raise UserInputError(
                f"{' and '.join(unread)}: --write writes the committed skill file only (to "
                "--skills-dir) and says how it moved; leave them out, or show the skill "
                "without --write"
            )
        for name in (check_task_name(task),) if task is not None else TASK_NAMES:
            refit_task(name, n_via_points, skills_dir)
        return
    if (task is None) == (demo is None):
        raise UserInputError("give exactly one of --task or --demo (or --write)")
    committed_only = given_options(ctx, "compare", "skills_dir") if demo is not None else []
    if committed_only:
        raise UserInputError(
            f"{' and '.join(committed_only)}: a task's committed skill's (--demo fits the "
            "demonstration afresh): give --task instead, or leave them out"
        )
    if task is not None:
        output = show_committed_skill(check_task_name(task), out_dir, n_via_points, skills_dir)
        committed = cast("CommittedSkill", output.committed)  # a committed skill's output
        provenance = committed.provenance
        typer.echo(
            f"committed skill {committed.path} (fitted at {provenance.get('code_commit')}, "
            f"numpy {provenance.get('libraries', {}).get('numpy')}, scipy "
            f"{provenance.get('libraries', {}).get('scipy')}, "
            f"{provenance.get('machine', {}).get('numerics')}; refit with --write)"
        )
        echo_hyperparameters(output.skill)
        if compare:
            echo_fresh_fit(task, output.skill, n_via_points)
    else:
        output = fit_demonstration(
            cast("Path", demo), out_dir, config=FitConfig(n_via_points=n_via_points)
        )
    worst = max(output.rmse["position"][:3])
    typer.echo(
        f"{'committed' if task else 'fitted'} {output.skill.name}: length scale "
        f"{output.skill.kernel.length_scale!r}, max position RMSE {worst * 1000:.3f} mm -> "
        f"{output.json_path}, {output.figure_path}"
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


def refit_task(task: str, n_via_points: int, skills_dir: Path | None) -> None:
    """Refit ``task``'s committed skill on this machine and say how it moved (`fit --write`)."""
    from distgprl.machine import machine_info
    from distgprl.skill.committed import committed_skill_path, read_skill_file
    from distgprl.skill.committed import refit_committed_skill as refit

    path = committed_skill_path(task, skills_dir)
    before = read_skill_file(path).skill if path.exists() else None
    written = refit(task, n_via_points, skills_dir)
    typer.echo(
        f"refitted {task} on this machine ({machine_info()['numerics']}): length scale "
        f"{written.skill.kernel.length_scale!r} -> {written.path}"
    )
    if before is not None and before.n_via_points == written.skill.n_via_points:
        typer.echo(f"  against the previous file: {difference_text(before, written.skill, task)}")


def echo_hyperparameters(skill: GPSkill) -> None:
    """Print the skill's fitted hyperparameters at full precision (``repr``)."""
    k = skill.kernel
    typer.echo(
        f"  shared kernel (standardised): length scale {k.length_scale!r}, signal variance "
        f"{k.signal_variance!r}, noise variance {k.noise_variance!r}"
    )
    for axis, kernel in zip(
        ("x", "y", "z", "rx", "ry", "rz"), skill.axis_kernels or (), strict=False
    ):
        typer.echo(
            f"  zero-mean K of {axis}: length scale {kernel.length_scale!r}, signal variance "
            f"{kernel.signal_variance!r}, noise variance {kernel.noise_variance!r}"
        )


def echo_fresh_fit(task: str, committed: GPSkill, n_via_points: int) -> None:
    """Print how a fresh fit on this machine differs from the committed skill (`--compare`)."""
    from distgprl.machine import machine_info
    from distgprl.skill.committed import fit_task_skill

    fresh = fit_task_skill(task, n_via_points)
    typer.echo(
        f"a fresh fit on this machine ({machine_info()['numerics']}) against the committed "
        f"skill: {difference_text(committed, fresh, task)}"
    )


def difference_text(old: GPSkill, new: GPSkill, task: str) -> str:
    """`fresh_fit_differences` as one line."""
    from distgprl.experiments.skills import fresh_fit_differences

    differences = fresh_fit_differences(old, new, task)
    if not any(differences.values()):
        return "identical bit for bit"
    return ", ".join(
        f"{key} {value:.2g} {'m/rad (abs)' if key == 'via_points' else 'rel'}"
        for key, value in differences.items()
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
