"""`distgprl tables`, `curves`, `render` and `bench`: the tables and figures made from
result files, an episode's rendering and the benchmarks."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from distgprl.cli.common import (
    METHODS_HELP,
    PRESETS_HELP,
    ConfigOption,
    PresetOption,
    RootOption,
    TaskOption,
    given_options,
    resolve_preset,
    user_errors,
)
from distgprl.errors import UserInputError


@user_errors
def bench(
    quick: Annotated[bool, typer.Option(help="Fewer repeats and timed steps.")] = False,
    out_dir: Annotated[Path, typer.Option(help="Output folder.")] = Path("results/bench"),
) -> None:
    """The paper's §V figures: adaptation latency, env step, SAC update, suite vs floor."""
    from distgprl.experiments.bench.markdown import markdown_table
    from distgprl.experiments.bench.run import load_results, run_benchmarks

    path = run_benchmarks(quick, out_dir, progress=typer.echo)
    typer.echo(markdown_table(load_results(path)))
    typer.echo(f"wrote {path}")


@user_errors
def tables(
    preset: PresetOption = None,
    config: ConfigOption = None,
    root: RootOption = Path("results"),
    out_dir: Annotated[Path, typer.Option(help="Output folder.")] = Path("paper_figures"),
    against: Annotated[
        str | None,
        typer.Option(
            metavar="NAME",
            help=f"Also pair every run TC by TC with the same run of this preset: {PRESETS_HELP}.",
        ),
    ] = None,
) -> None:
    """Table I (and Table II if hardware trials exist) as CSV, Markdown and LaTeX."""
    from distgprl.config import preset_names
    from distgprl.report.tables import write_tables

    preset = resolve_preset(preset, config)
    if against is not None and against not in preset_names() and not (root / against).is_dir():
        raise UserInputError(
            f"--against {against}: not a preset (valid presets: {', '.join(preset_names())}) "
            f"and no results under {root / against}"
        )
    for path in write_tables(root, preset, out_dir, against):
        typer.echo(f"wrote {path}")


@user_errors
def curves(
    preset: PresetOption = None,
    config: ConfigOption = None,
    root: RootOption = Path("results"),
    out_dir: Annotated[Path, typer.Option(help="Output folder.")] = Path("paper_figures"),
) -> None:
    """Learning-curve figures (HAP effect, covariance effect, all methods), PNG and PDF."""
    from distgprl.report.curves import write_curves

    preset = resolve_preset(preset, config)
    for path in write_curves(root, preset, out_dir):
        typer.echo(f"wrote {path}")


@user_errors
def render(
    ctx: typer.Context,
    task: TaskOption,
    out: Annotated[
        Path | None,
        typer.Option(
            help="Output image: .png (one frame) or .gif (default: TASK_METHOD_seedS.png in the "
            "current folder, TASK_demo.png for the skill alone)."
        ),
    ] = None,
    tc: Annotated[int | None, typer.Option(help="Evaluation TC index (default: nominal).")] = None,
    method: Annotated[
        str,
        typer.Option(
            metavar="METHOD",
            help=f"Method: {METHODS_HELP}. demo: the GP skill alone; any other: the trained "
            "run's adapted episode beside the unadapted demonstration (faded), windows marked.",
        ),
    ] = "demo",
    seed: Annotated[int, typer.Option(help="Seed of the trained run.")] = 0,
    preset: PresetOption = None,
    config: ConfigOption = None,
    root: RootOption = Path("results"),
    policy: Annotated[
        str,
        typer.Option(
            metavar="best|final",
            help="The run's best policy (Table I's, shipped with the run: no training needed "
            "on a fresh clone) or its final one (needs the run's model.zip).",
        ),
    ] = "best",
) -> None:
    """Render an episode (headless): the GP skill, or a trained policy's adaptation."""
    from distgprl.data import check_task_name

    check_task_name(task)
    out = out if out is not None else default_render_path(task, method, seed)
    if method == "demo":
        run_only = given_options(ctx, "seed", "preset", "config", "root", "policy")
        if run_only:
            raise UserInputError(
                f"{', '.join(run_only)}: a trained run's (--method demo renders the GP skill "
                "alone, from no run): give a trained --method, or leave them out"
            )
        from distgprl.envs.render import render_demo_episode

        summary = render_demo_episode(task, tc, out)
    else:
        from distgprl.api import load_policy
        from distgprl.envs.render import render_policy_episode
        from distgprl.experiments.factories import make_env
        from distgprl.identity import resolve_run

        preset = resolve_preset(preset, config)
        trained = load_policy(task, method, seed, preset=preset, root=root, policy=policy)
        env = make_env(trained.run)
        demo_env = make_env(resolve_run(task, "demo", seed, preset))
        try:
            summary = render_policy_episode(
                env, trained, demo_env, tc, out, title=f"{method} seed {seed} ({policy})"
            )
        finally:
            env.close()
            demo_env.close()
    typer.echo(
        rendered_line(out, summary, "GP skill" if method == "demo" else f"{method} seed {seed}")
    )


def default_render_path(task: str, method: str, seed: int) -> Path:
    """Where `render` writes without ``--out``: ``dcp_dist-gprl_seed0.png`` (``dcp_demo.png``
    for the skill alone), in the current folder."""
    return Path(f"{task}_demo.png" if method == "demo" else f"{task}_{method}_seed{seed}.png")


def _outcome_text(summary: dict, prefix: str = "") -> str:
    """``success, min clearance 16.5 mm`` (or ``collision`` / ``not completed``) of one episode of a
    render summary (keys ``<prefix>success``, ``collision``, ``min_clearance`` in m)."""
    if summary[f"{prefix}collision"]:
        outcome = "collision"
    else:
        outcome = "success" if summary[f"{prefix}success"] else "not completed"
    return f"{outcome}, min clearance {1e3 * summary[f'{prefix}min_clearance']:.1f} mm"


def rendered_line(out: Path, summary: dict, label: str) -> str:
    """What `render` wrote, in one line: the TC, the episode's outcome and minimum clearance
    and, for a trained run, the unadapted demonstration's beside it; the frame count."""
    tc = "nominal TC" if summary["tc_index"] is None else f"evaluation TC {summary['tc_index']}"
    text = f"wrote {out} ({summary['frames']} frame(s)): {tc}; {label}: {_outcome_text(summary)}"
    if "demo_success" in summary:
        text += f"; demonstration: {_outcome_text(summary, 'demo_')}"
    return text
