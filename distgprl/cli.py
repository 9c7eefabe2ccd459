"""The `distgprl` command line: each command parses, loads a config, calls one function.

Bad input (unknown names, invalid files) exits with code 2 and one line on stderr.
"""

from __future__ import annotations

import functools
import sys
from pathlib import Path
from typing import Annotated, Literal

import typer
from typer.core import TyperCommand, TyperGroup

from distgprl import __version__
from distgprl.config import register_preset, shipped_presets
from distgprl.data import TASK_NAMES
from distgprl.errors import UserInputError
from distgprl.identity import SWEEP_SEEDS
from distgprl.methods import METHODS


def _plain_flags(params: list) -> list:
    """``params`` with no type shown for flags: they take no value, so typer's ``<bool>`` in
    the help only reads as if they did."""
    for param in params:
        if getattr(param, "is_flag", False) and param.metavar is None:
            param.metavar = ""
    return params


class _Command(TyperCommand):
    """A typer command whose help shows no ``<bool>`` for flags (`_plain_flags`)."""

    def get_params(self, ctx):
        return _plain_flags(super().get_params(ctx))


class _Group(TyperGroup):
    """The typer group of `_Command`: the same for the top-level options."""

    def get_params(self, ctx):
        return _plain_flags(super().get_params(ctx))


app = typer.Typer(
    cls=_Group,
    add_completion=False,
    no_args_is_help=True,
    help="Dist-GPRL reproduction: fit, simulate, train, evaluate, report.",
)
_command = functools.partial(app.command, cls=_Command)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"distgprl {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_version, is_eager=True, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    """Dist-GPRL reproduction: fit, simulate, train, evaluate, report."""


def _user_errors(func):
    """Turn `UserInputError` into one clear line on stderr and exit code 2."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except UserInputError as exc:
            typer.echo(f"error: {exc}", err=True)
            raise typer.Exit(code=2) from None

    return wrapper


# Names the options take, for their help.
_TRAINABLE = " | ".join(name for name, spec in METHODS.items() if spec.trainable)
_METHODS = " | ".join(METHODS)
_TASKS = " | ".join(TASK_NAMES)
_PRESETS = " | ".join(shipped_presets())

# Options several commands share.
RootOption = Annotated[
    Path, typer.Option(help="Results root folder (runs go to <root>/<preset>/...).")
]
PresetOption = Annotated[
    str | None,
    typer.Option(
        metavar="NAME",
        help=f"Shipped preset: {_PRESETS} (default paper).",
        show_default=False,
    ),
]
ConfigOption = Annotated[
    Path | None,
    typer.Option(
        "--config",
        metavar="PATH",
        help="Your own preset YAML instead of --preset (the presets' schema); the preset's "
        "name is the file stem, which must not be a shipped preset's.",
    ),
]
MethodsOption = Annotated[
    str | None, typer.Option(help=f"Comma-separated methods (default all): {_METHODS}.")
]
TasksOption = Annotated[
    str | None, typer.Option(help=f"Comma-separated tasks (default all): {_TASKS}.")
]
SeedsOption = Annotated[str, typer.Option(help="Comma-separated seeds.")]
DEFAULT_SEEDS = ",".join(str(seed) for seed in SWEEP_SEEDS)
TaskOption = Annotated[str, typer.Option(metavar="TASK", help=f"Task: {_TASKS}.")]


def _preset(preset: str | None, config: Path | None) -> str:
    """The preset a command runs: ``--preset`` (default ``paper``), or the user's ``--config``
    file registered under its stem (`register_preset`)."""
    if config is None:
        return preset or "paper"
    if preset is not None:
        raise UserInputError("give --preset or --config, not both")
    return register_preset(config)


def _runs(count: int) -> str:
    return f"{count} run" if count == 1 else f"{count} runs"


@_command()
@_user_errors
def fit(
    task: Annotated[
        str | None, typer.Option(metavar="TASK", help=f"Fit the task's shipped demo: {_TASKS}.")
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
    source = demo_path(task) if task is not None else demo
    output = fit_demonstration(
        source, out_dir, name=task, config=FitConfig(n_via_points=n_via_points)
    )
    worst = max(output.rmse["position"][:3])
    typer.echo(
        f"fitted {output.skill.name}: length scale {output.skill.kernel.length_scale:.4f}, "
        f"max position RMSE {worst * 1000:.3f} mm -> {output.json_path}, {output.figure_path}"
    )
    correlation = output.correlation
    windows = correlation["windows"]
    typer.echo(
        f"covariance transform (lambda {correlation['correlation_lambda']:g}, K scale "
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
    for scale, spectrum in correlation["candidates"].items():
        typer.echo(
            f"  candidate K scale {scale!r}: S_W eigenvalues "
            f"{spectrum['eigenvalue_min']:.3f}-{spectrum['eigenvalue_max']:.3f}"
        )


@_command()
@_user_errors
def hardware(
    trials: Annotated[int, typer.Option(min=1, help="Number of trials.")] = 10,
    method: Annotated[
        str, typer.Option(metavar="METHOD", help=f"Trained method whose policy adapts: {_METHODS}.")
    ] = "dist-gprl",
    seed: Annotated[int, typer.Option(help="Seed of the trained run.")] = 0,
    backend: Annotated[
        str | None, typer.Option(help="twin | ur (default: ur if --robot-ip, else twin).")
    ] = None,
    robot_ip: Annotated[
        str | None, typer.Option(help="UR controller address (ur backend).")
    ] = None,
    camera: Annotated[str | None, typer.Option(help="Camera index or URL (ur backend).")] = None,
    calibration: Annotated[Path | None, typer.Option(help="Calibration YAML/JSON.")] = None,
    dry_run: Annotated[bool, typer.Option(help="Perceive, adapt and check; never move.")] = False,
    judge: Annotated[
        str, typer.Option(metavar="auto|operator", help="Who judges success.")
    ] = "auto",
    force: Annotated[
        bool, typer.Option(help="Execute plans that fail the pre-flight check.")
    ] = False,
    preset: PresetOption = None,
    config: ConfigOption = None,
    model: Annotated[Path | None, typer.Option(help="Model file instead of the run's.")] = None,
    root: RootOption = Path("results"),
    repair: Annotated[
        bool,
        typer.Option(
            help="Retime too-fast plans before refusing (with --repair-push also push "
            "too-close via-points; --no-repair: refuse at once)."
        ),
    ] = True,
    sensor_noise: Annotated[
        int,
        typer.Option(min=0, max=2, help="Twin sensor noise: 0 none, 1 mild, 2 strong."),
    ] = 0,
    repair_push: Annotated[
        bool,
        typer.Option(
            help="Also push too-close via-points along the distance field (off by default: "
            "not yet shown to make a grazing plan safer, see RepairConfig)."
        ),
    ] = False,
) -> None:
    """Hardware trials on a UR5e (ur_rtde) or its digital twin; one CSV row per trial."""
    from distgprl.hardware.repair import RepairConfig
    from distgprl.hardware.trials import run_trials

    preset = _preset(preset, config)
    report = run_trials(
        trials=trials,
        method=method,
        seed=seed,
        backend=backend or ("ur" if robot_ip else "twin"),
        robot_ip=robot_ip,
        camera=camera,
        calibration=calibration,
        dry_run=dry_run,
        judge=judge,
        force=force,
        root=root,
        preset=preset,
        model_path=model,
        repair=repair,
        repair_config=RepairConfig(repair=repair_push),
        sensor_noise=sensor_noise,
    )
    typer.echo(f"{report.path}: {report.summary}")


@_command()
@_user_errors
def bench(
    quick: Annotated[bool, typer.Option(help="Fewer repeats and smaller sweeps (~1 min).")] = False,
    out_dir: Annotated[Path, typer.Option(help="Output folder.")] = Path("results/bench"),
) -> None:
    """Adaptation latency, simulation and training throughput, scaling; JSON + figure."""
    from distgprl.experiments.bench import load_results, markdown_table, run_benchmarks

    path = run_benchmarks(quick, out_dir, progress=typer.echo)
    typer.echo(markdown_table(load_results(path)))
    typer.echo(f"wrote {path}")


def _split(text: str | None) -> list[str] | None:
    return [item.strip() for item in text.split(",") if item.strip()] if text else None


def _seeds(text: str) -> list[int]:
    try:
        return [int(s) for s in _split(text) or []]
    except ValueError:
        raise UserInputError(f"--seeds must be comma-separated integers, got {text!r}") from None


@_command()
@_user_errors
def sweep(
    preset: PresetOption = None,
    config: ConfigOption = None,
    methods: MethodsOption = None,
    tasks: TasksOption = None,
    seeds: SeedsOption = DEFAULT_SEEDS,
    workers: Annotated[
        int | None,
        typer.Option(min=1, help="Parallel jobs (default: one per CPU core this process may use)."),
    ] = None,
    executor: Annotated[
        Literal["local", "ray"], typer.Option(help="Where the jobs run (ray: extra distgprl[ray]).")
    ] = "local",
    address: Annotated[str | None, typer.Option(help="Ray cluster address (ray executor).")] = None,
    root: RootOption = Path("results"),
    heartbeat: Annotated[
        float,
        typer.Option(min=0, help="Minutes between progress reports of running jobs (0: off)."),
    ] = 5.0,
    retrain_damaged: Annotated[
        bool, typer.Option(help="Delete damaged runs (see `status`) and train them anew.")
    ] = False,
) -> None:
    """Train and evaluate every (method, task, seed); finished runs are skipped.

    Exit code 0: every run is complete; 1: a run failed (its error.json says why) or is
    damaged (reported, left alone without --retrain-damaged); 3: no failure, but runs were
    left to another process training them (busy); 130: interrupted.
    """
    from distgprl.experiments.status import sweep_status
    from distgprl.experiments.sweep import (
        default_workers,
        plan_jobs,
        run_sweep,
        stop_on_interrupt_signals,
    )

    preset = _preset(preset, config)
    jobs = plan_jobs(preset, _split(methods), _split(tasks), _seeds(seeds), root)
    if workers is None:
        workers = default_workers()
    typer.echo(f"sweep: {_runs(len(jobs))} ({preset} preset), {workers} parallel job(s)")

    def report(result, finished, total):
        extra = f" ({result.error})" if result.error else ""
        typer.echo(
            f"[{finished}/{total}] {result.job.name}: {result.status} "
            f"in {result.seconds:.0f} s{extra}"
        )

    def progress(unfinished):
        for status in sweep_status(unfinished):
            if status.state == "running":
                typer.echo(f"  {status.describe()}")

    stop_on_interrupt_signals()
    try:
        results = run_sweep(
            jobs,
            workers,
            executor,
            address,
            on_result=report,
            on_tick=progress if heartbeat > 0 else None,
            tick_s=heartbeat * 60.0,
            retrain_damaged=retrain_damaged,
        )
    except KeyboardInterrupt:
        typer.echo(
            "sweep interrupted: queued runs were not started and running ones stopped at "
            "their last checkpoint; re-run the same command to resume.",
            err=True,
        )
        raise typer.Exit(code=130) from None
    failed = [r for r in results if r.status == "failed"]
    busy = [r for r in results if r.status == "busy"]
    damaged = [r for r in results if r.status == "damaged"]
    typer.echo(
        f"sweep: {len(results) - len(failed) - len(busy) - len(damaged)}/{len(results)} runs "
        "complete"
        + (f", {len(busy)} left to the other process training them" if busy else "")
        + (f", {len(damaged)} damaged (--retrain-damaged retrains them)" if damaged else "")
    )
    if failed or damaged:
        raise typer.Exit(code=1)
    if busy:  # not complete yet: `make reproduce` must not go on to the tables as if it were
        raise typer.Exit(code=3)


@_command()
@_user_errors
def status(
    preset: PresetOption = None,
    config: ConfigOption = None,
    methods: MethodsOption = None,
    tasks: TasksOption = None,
    seeds: SeedsOption = DEFAULT_SEEDS,
    root: RootOption = Path("results"),
    workers: Annotated[
        int | None,
        typer.Option(
            min=1, help="Parallel jobs to estimate the time left for (default: as `sweep`)."
        ),
    ] = None,
) -> None:
    """Where every run of a sweep stands (done, running, partial, ...), from its run folder,
    and the training time left."""
    from distgprl.experiments.status import count_states, sweep_status, training_left
    from distgprl.experiments.sweep import default_workers, plan_jobs

    preset = _preset(preset, config)
    statuses = sweep_status(plan_jobs(preset, _split(methods), _split(tasks), _seeds(seeds), root))
    for entry in statuses:
        typer.echo(entry.describe())
    typer.echo(count_states(statuses))
    typer.echo(training_left(statuses).describe(workers or default_workers()))


@_command()
@_user_errors
def tables(
    preset: PresetOption = None,
    config: ConfigOption = None,
    root: RootOption = Path("results"),
    out_dir: Annotated[Path, typer.Option(help="Output folder.")] = Path("paper_figures"),
    against: Annotated[
        str | None,
        typer.Option(
            metavar="NAME",
            help=f"Also pair every run TC by TC with the same run of this preset: {_PRESETS}.",
        ),
    ] = None,
) -> None:
    """Table I (and Table II if hardware trials exist) as CSV, Markdown and LaTeX."""
    from distgprl.config import preset_names
    from distgprl.report.tables import write_tables

    preset = _preset(preset, config)
    if against is not None and against not in preset_names() and not (root / against).is_dir():
        raise UserInputError(
            f"--against {against}: not a preset (valid presets: {', '.join(preset_names())}) "
            f"and no results under {root / against}"
        )
    for path in write_tables(root, preset, out_dir, against):
        typer.echo(f"wrote {path}")


@_command()
@_user_errors
def curves(
    preset: PresetOption = None,
    config: ConfigOption = None,
    root: RootOption = Path("results"),
    out_dir: Annotated[Path, typer.Option(help="Output folder.")] = Path("paper_figures"),
) -> None:
    """Learning-curve figures (HAP effect, covariance effect, all methods), PNG and PDF."""
    from distgprl.report.curves import write_curves

    preset = _preset(preset, config)
    for path in write_curves(root, preset, out_dir):
        typer.echo(f"wrote {path}")


def main() -> None:
    """Console entry for `python -m distgprl` and `python -m distgprl.cli`."""
    app(prog_name="distgprl")


@_command()
@_user_errors
def train(
    method: Annotated[str, typer.Option(metavar="METHOD", help=f"Method: {_TRAINABLE}.")],
    task: TaskOption,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    preset: PresetOption = None,
    config: ConfigOption = None,
    steps: Annotated[
        int | None,
        typer.Option(
            help="Override the preset's total RL steps: a positive multiple of the episode "
            "length (3 RL steps, one per window).",
            show_default=False,
        ),
    ] = None,
    resume: Annotated[
        bool, typer.Option(help="Continue a killed run from its checkpoint.")
    ] = False,
    root: RootOption = Path("results"),
    evaluate: Annotated[bool, typer.Option(help="Evaluate after training.")] = True,
) -> None:
    """Train one method on one task and seed (resumable); then evaluate it.

    Interrupted (Ctrl-C, SIGINT or SIGTERM): says where it stopped and how to resume; exit 130.
    """
    from distgprl.experiments.runner import describe_interrupt, resume_command, train_run
    from distgprl.experiments.sweep import stop_on_interrupt_signals

    preset = _preset(preset, config)
    stop_on_interrupt_signals()
    try:
        folder = train_run(task, method, seed, preset, steps, resume, root, evaluate_after=evaluate)
    except KeyboardInterrupt as stop:
        command = resume_command(task, method, seed, preset, steps, root, evaluate)
        typer.echo(describe_interrupt(stop, command), err=True)
        raise typer.Exit(code=130) from None
    typer.echo(f"trained {task}/{method}/seed{seed} -> {folder}")


@_command()
@_user_errors
def evaluate(
    method: Annotated[
        str,
        typer.Option(metavar="METHOD", help=f"Method (demo: the unadapted reference): {_METHODS}."),
    ],
    task: TaskOption,
    seed: Annotated[int, typer.Option(help="Seed of the trained run.")] = 0,
    preset: PresetOption = None,
    config: ConfigOption = None,
    episodes: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="Evaluation TCs (default: preset). Another number writes a supplementary "
            "evaluation_n<N>.csv / summary_n<N>.json (first N TCs of the same stream) "
            "beside the preset's.",
        ),
    ] = None,
    root: RootOption = Path("results"),
    policy: Annotated[
        str,
        typer.Option(
            metavar="final|best",
            help="`final` (the trained policy, what Table I evaluates) or `best` (Algorithm "
            "1's best policy: the best learning-curve point, by curve success, then collision, "
            "then return), which writes evaluation_best*.csv / summary_best*.json.",
        ),
    ] = "final",
    plan_repair: Annotated[
        bool,
        typer.Option(
            "--plan-repair",
            help="Put the hardware safety layer between each window plan and execution: "
            "pre-flight check, retime what is too fast, refuse what is still unsafe (the "
            "episode stops there). Writes evaluation_repair.csv / summary_repair.json beside "
            "the plain evaluation.",
        ),
    ] = False,
    repair_push: Annotated[
        bool,
        typer.Option(
            "--repair-push",
            help="With --plan-repair: also push via-points out of the clearance margin along "
            "the distance field's gradient (evaluation_repair_push.csv).",
        ),
    ] = False,
) -> None:
    """Evaluate a trained policy (deterministic) on the fixed evaluation TCs."""
    from distgprl.experiments.runner import describe, evaluate_run

    preset = _preset(preset, config)
    if repair_push and not plan_repair:
        raise UserInputError("--repair-push needs --plan-repair")
    if plan_repair:
        from distgprl.experiments.repaired_evaluation import evaluate_with_repair
        from distgprl.hardware.repair import RepairConfig

        summary = evaluate_with_repair(
            task, method, seed, preset, episodes, root, policy, RepairConfig(repair=repair_push)
        )
    else:
        summary = evaluate_run(task, method, seed, preset, episodes, root, policy=policy)
    typer.echo(describe(summary))


@_command()
@_user_errors
def render(
    task: TaskOption,
    out: Annotated[Path, typer.Option(help="Output image: .png (one frame) or .gif.")],
    tc: Annotated[int | None, typer.Option(help="Evaluation TC index (default: nominal).")] = None,
    method: Annotated[
        str,
        typer.Option(
            metavar="METHOD",
            help=f"Method: {_METHODS}. demo: the GP skill alone; any other: the trained "
            "run's adapted episode beside the unadapted demonstration (faded), windows marked.",
        ),
    ] = "demo",
    seed: Annotated[int, typer.Option(help="Seed of the trained run.")] = 0,
    preset: PresetOption = None,
    config: ConfigOption = None,
    root: RootOption = Path("results"),
    policy: Annotated[
        str, typer.Option(metavar="final|best", help="The run's final or best policy.")
    ] = "final",
) -> None:
    """Render an episode (headless): the GP skill, or a trained policy's adaptation."""
    from distgprl.data import check_task_name

    check_task_name(task)
    if method == "demo":
        from distgprl.envs.render import render_demo_episode

        summary = render_demo_episode(task, tc, out)
    else:
        from distgprl.api import load_policy
        from distgprl.envs.render import render_policy_episode
        from distgprl.experiments.runner import make_env, resolve_run

        preset = _preset(preset, config)
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
    typer.echo(f"wrote {out}: " + ", ".join(f"{k}={v}" for k, v in summary.items() if k != "path"))


@_command()
@_user_errors
def hap(
    task: TaskOption,
    out: Annotated[
        Path | None, typer.Option(help="Figure path (default results/hap/<task>.png).")
    ] = None,
) -> None:
    """Build (or load) the task's HAP safe subspace; report it and plot C_safe."""
    from distgprl.data import check_task_name
    from distgprl.envs.tasks import load_task_subspace
    from distgprl.safety.hap import plot_subspace
    from distgprl.sim.tasks import get_task

    check_task_name(task)
    subspace, loaded = load_task_subspace(task)
    stats = subspace.stats
    out = out or Path("results/hap") / f"{task}.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    sim = get_task(task).make_sim()
    try:
        plot_subspace(subspace, sim.obstacle_shapes(), out, title=f"{task.upper()} C_safe")
    finally:
        sim.close()
    typer.echo(
        f"{task}: C_safe {len(subspace.unique_positions)} positions "
        f"({stats.n_mapped}/{stats.n_reachable} reachable poses mapped), "
        f"build {stats.build_seconds:.1f} s{' (cached)' if loaded else ''} -> {out}"
    )


if __name__ == "__main__":
    sys.exit(main())
