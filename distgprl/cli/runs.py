"""`distgprl train`, `evaluate`, `sweep` and `status`: train and evaluate runs, one or a
whole sweep, and see where a sweep stands."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Annotated, Literal

import typer

from distgprl.cli.common import (
    METHODS_HELP,
    TRAINABLE_HELP,
    ConfigOption,
    MethodsOption,
    PresetOption,
    RootOption,
    SeedsOption,
    SetOption,
    SweepPresetOption,
    TaskOption,
    TasksOption,
    given_options,
    parse_seeds,
    resolve_preset,
    runs_text,
    split_list,
    user_errors,
)
from distgprl.errors import UserInputError
from distgprl.experiments.table2_trials import TABLE2_TRIALS
from distgprl.studies import get_study, is_study, study_of_reading
from distgprl.trial_protocol import TABLE2_POLICY


@user_errors
def sweep(
    ctx: typer.Context,
    preset: SweepPresetOption = None,
    config: ConfigOption = None,
    overrides: SetOption = None,
    methods: MethodsOption = None,
    tasks: TasksOption = None,
    seeds: SeedsOption = None,
    workers: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="Parallel jobs (default: one per CPU core this process may use). On a Ray "
            "cluster (--address) its CPUs say how many run at once; --workers then only sizes "
            "the progress report's estimate.",
        ),
    ] = None,
    executor: Annotated[
        Literal["local", "ray"], typer.Option(help="Where the jobs run (ray: extra distgprl[ray]).")
    ] = "local",
    address: Annotated[
        str | None,
        typer.Option(
            help="Ray cluster address HOST:PORT (ray executor; without it, a Ray instance on "
            "this machine). Every node must see --root at the same path: "
            "docs/guides/slurm.md."
        ),
    ] = None,
    root: RootOption = Path("results"),
    heartbeat: Annotated[
        float,
        typer.Option(
            min=0,
            help="Minutes between plain progress reports (the sweep and its running jobs) "
            "when stdout is not a terminal (0: none); a terminal gets a live display.",
        ),
    ] = 5.0,
    retrain_damaged: Annotated[
        bool, typer.Option(help="Delete damaged runs (see `status`) and train them anew.")
    ] = False,
    twin_trials: Annotated[
        int,
        typer.Option(
            min=0,
            help="Digital-twin trials per Table II setting each DBM run gets right after "
            "training, while its model is on disk (seven settings: the paper's protocol, the "
            "safety layer with repair on and off, and with repair on at noise levels 1-4); "
            "0: none.",
        ),
    ] = TABLE2_TRIALS,
    trial_policy: Annotated[
        str,
        typer.Option(
            metavar="final|best",
            help="The trained policy the twin trials run: final (the run's model.zip, on "
            "disk where it was trained; Table II's) or best (the best policy the run ships, "
            "Table I's; Table II's three noise-free settings, tabulated beside Table II).",
        ),
    ] = TABLE2_POLICY,
    repair_evaluations: Annotated[
        bool,
        typer.Option(
            help="Evaluate each finished run with the hardware safety layer in the loop "
            "(check only; retime, then refuse), while its model is on disk: the "
            "'Table I + repair' of `distgprl tables`.",
        ),
    ] = True,
) -> None:
    """Train and evaluate every (method, task, seed); finished runs are skipped.

    Exit code 0: every run is complete; 1: a run failed (its error.json says why) or is
    damaged (reported, left alone without --retrain-damaged); 3: no failure, but runs were
    left to another process training them (busy); 4: the Ray cluster was lost (its head
    stopped answering: restart it and re-run the same command); 130: interrupted.
    """
    from distgprl.experiments.ray_executor import CLUSTER_LOST_EXIT, ClusterLostError
    from distgprl.experiments.sweep import (
        default_workers,
        plan_jobs,
        run_sweep,
        stop_on_interrupt_signals,
    )
    from distgprl.experiments.sweep_progress import SweepProgress
    from distgprl.experiments.sweep_record import record_request

    preset = resolve_preset(preset, config, overrides)
    asked = (split_list(methods), split_list(tasks), parse_seeds(seeds))
    jobs = plan_jobs(preset, *asked, root, twin_trials, repair_evaluations, trial_policy)
    refuse_unread_sweep_options(
        ctx, jobs, is_study(preset), executor, address, twin_trials, repair_evaluations
    )
    workers = workers or default_workers()  # --workers is at least 1
    if is_study(preset):
        from distgprl.experiments.operator_study import write_study_reach

        study = get_study(preset)
        typer.echo(f"study {study.name}: readings {', '.join(study.presets)}; {study.question}")
        if study.reads_the_operator:
            typer.echo(f"wrote {write_study_reach(root, study)}")
    # on a Ray cluster its CPUs say how many jobs run at once, not --workers
    where = f"on the ray cluster at {address}" if executor == "ray" and address else ""
    typer.echo(
        f"sweep: {runs_text(len(jobs))} ({preset} preset) into {root}, "
        + (where or f"{workers} parallel job(s)")
    )
    recorded: list[bool] = []

    def record() -> None:  # what `status` reports; on Ray once the cluster answered
        if not recorded:
            record_request(root, preset, *asked)
            recorded.append(True)

    if executor == "local":
        record()
    progress = SweepProgress(jobs, workers)

    def on_result(result, count, total):
        record()
        progress.finished(result, count, total)

    for line in progress.opening(root):
        typer.echo(line)
    if progress.live:  # redrawn in place every second; the heartbeat is its running lines
        on_tick, tick_s = progress.tick, 1.0
    else:  # plain lines: the sweep's line after each finished run, running jobs every beat

        def on_tick(unfinished):
            progress.tick(unfinished)
            progress.heartbeat()

        tick_s = heartbeat * 60.0
    stop_on_interrupt_signals()
    try:
        results = run_sweep(
            jobs,
            workers,
            executor,
            address,
            on_result=on_result,
            on_tick=on_tick if tick_s > 0 else None,
            tick_s=tick_s,
            retrain_damaged=retrain_damaged,
        )
    except KeyboardInterrupt:
        progress.close()
        typer.echo(
            "sweep interrupted: queued runs were not started and running ones stopped at "
            "their last checkpoint; re-run the same command to resume "
            f"(`distgprl status --preset {preset} --root {root}` says where each resumes).",
            err=True,
        )
        raise typer.Exit(code=130) from None
    except ClusterLostError as lost:
        progress.close()
        typer.echo(str(lost), err=True)
        # Ray's driver cannot shut down without its head (it would wait for it, then abort
        # with a traceback): leave at once, the result files are all written already.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(CLUSTER_LOST_EXIT)
    progress.close()
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


def refuse_unread_sweep_options(
    ctx: typer.Context,
    jobs: list,
    study: bool,
    executor: str,
    address: str | None,
    twin_trials: int,
    repair_evaluations: bool,
) -> None:
    """A `UserInputError` for a `sweep` option that none of its ``jobs`` would read:
    ``--address`` without ``--executor ray``; ``--twin-trials N`` or ``--repair-evaluations``
    given for a study (``study``: its runs have no follow-ups); ``--twin-trials N`` for a
    sweep without a DBM run; ``--repair-evaluations`` for residual-control methods only.
    Their defaults apply where they can and are never refused."""
    from distgprl.methods import NO_SAFETY_LAYER, get_method, has_via_point_plan

    if address is not None and executor != "ray":
        raise UserInputError(
            "--address is a Ray cluster's: use it with --executor ray (the local executor "
            "runs the jobs on this machine)"
        )
    given = given_options(ctx, "twin_trials", "repair_evaluations", "trial_policy")
    if "--trial-policy" in given and twin_trials == 0:
        raise UserInputError(
            "--trial-policy names the policy the twin trials run, and --twin-trials 0 runs "
            "none: give --twin-trials N, or leave --trial-policy out"
        )
    asked_trials = twin_trials > 0 and bool({"--twin-trials", "--trial-policy"} & set(given))
    asked_repairs = repair_evaluations and "--repair-evaluations" in given
    if study and (asked_trials or asked_repairs):
        raise UserInputError(
            f"{' and '.join(given)}: a study's runs have no follow-ups (the twin trials and "
            "safety-layer evaluations are Table I's): leave them out, or sweep a preset"
        )
    if asked_trials and not any(job.task == "dbm" for job in jobs):
        raise UserInputError(
            "--twin-trials: the twin trials are Table II's, of DBM runs, and this sweep has "
            "none: add dbm to --tasks, or leave --twin-trials out"
        )
    if asked_repairs and not any(has_via_point_plan(get_method(job.method)) for job in jobs):
        raise UserInputError(f"--repair-evaluations: {NO_SAFETY_LAYER}")


@user_errors
def status(
    preset: SweepPresetOption = None,
    config: ConfigOption = None,
    methods: MethodsOption = None,
    tasks: TasksOption = None,
    seeds: SeedsOption = None,
    root: RootOption = Path("results"),
    workers: Annotated[
        int | None,
        typer.Option(
            min=1, help="Parallel jobs to estimate the time left for (default: as `sweep`)."
        ),
    ] = None,
) -> None:
    """Where every run of a sweep stands (done, running, partial, ...), from its run folder,
    the training time left and what the done runs' training took (hours, CPU-hours).

    Without --methods, --tasks and --seeds: the runs the sweeps into --root asked for (all
    of the preset's if none was recorded)."""
    from distgprl.experiments.pace import training_done, training_left
    from distgprl.experiments.status import count_states, sweep_status
    from distgprl.experiments.sweep import default_workers, plan_jobs
    from distgprl.experiments.sweep_record import recorded_requests, requested_jobs

    preset = resolve_preset(preset, config)
    asked = (split_list(methods), split_list(tasks), parse_seeds(seeds))
    jobs = requested_jobs(root, preset) if asked == (None, None, None) else None
    if jobs is not None:
        requests = len(recorded_requests(root, preset))
        typer.echo(
            f"the runs the sweeps into {root} asked for ({requests} request(s); "
            "--methods, --tasks or --seeds for others):"
        )
    statuses = sweep_status(jobs if jobs is not None else plan_jobs(preset, *asked, root))
    for entry in statuses:
        typer.echo(entry.describe())
    typer.echo(count_states(statuses))
    if not (Path(root) / preset).is_dir():
        typer.echo(
            f"no run of the {preset} preset in {root} (a sweep into another folder: its --root)"
        )
    reference = []  # a study's first runs take the pace of its reference preset's
    study = get_study(preset) if is_study(preset) else study_of_reading(preset)
    if study is not None:
        reference = sweep_status(plan_jobs(study.reference.preset, list(study.methods), root=root))
    typer.echo(training_left(statuses, reference=reference).describe(workers or default_workers()))
    typer.echo(training_done(statuses).describe())
    finished = [
        (entry.job.task, entry.job.method, entry.job.seed)
        for entry in statuses
        if entry.state == "done"
    ]
    if is_study(preset):  # a study's runs have no follow-ups (twin trials, repair evaluations)
        return
    finished_dbm = [(method, seed) for task, method, seed in finished if task == "dbm"]
    if finished_dbm:
        from distgprl.experiments.table2_trials import coverage

        typer.echo(coverage(root, preset, finished_dbm).describe())
    if finished:
        from distgprl.experiments.repair_follow_ups import coverage as repair_coverage

        typer.echo(repair_coverage(root, preset, finished).describe())


@user_errors
def train(
    method: Annotated[str, typer.Option(metavar="METHOD", help=f"Method: {TRAINABLE_HELP}.")],
    task: TaskOption,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    preset: PresetOption = None,
    config: ConfigOption = None,
    overrides: SetOption = None,
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
    from distgprl.experiments.run_control import describe_interrupt, resume_command
    from distgprl.experiments.sweep import stop_on_interrupt_signals
    from distgprl.experiments.training import train_run

    preset = resolve_preset(preset, config, overrides)
    stop_on_interrupt_signals()
    try:
        folder = train_run(task, method, seed, preset, steps, resume, root, evaluate_after=evaluate)
    except KeyboardInterrupt as stop:
        command = resume_command(task, method, seed, preset, steps, root, evaluate)
        typer.echo(describe_interrupt(stop, command), err=True)
        raise typer.Exit(code=130) from None
    typer.echo(f"trained {task}/{method}/seed{seed} -> {folder}")
    if evaluate and (folder / "summary.json").exists():
        from distgprl.experiments.evaluation import summary_table
        from distgprl.schema import read_json

        summary = read_json(folder / "summary.json")["summary"]
        typer.echo(summary_table(summary, f"evaluation ({folder / 'summary.json'}):"))
    else:
        import shlex

        words = ["distgprl", "evaluate", "--method", method, "--task", task, "--seed", str(seed)]
        words += ["--preset", preset, "--root", str(root)]
        typer.echo(f"not evaluated (--no-evaluate); evaluate with: {shlex.join(words)}")


@user_errors
def evaluate(
    ctx: typer.Context,
    method: Annotated[
        str,
        typer.Option(
            metavar="METHOD", help=f"Method (demo: the unadapted reference): {METHODS_HELP}."
        ),
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
            help="`final` (the policy at the run's last step: Table I of the final policy) or "
            "`best` (Algorithm 1's best policy, what Table I reports: the best trained "
            "learning-curve point, by curve success, then collision, then return), which "
            "writes evaluation_best*.csv / summary_best*.json.",
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
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the whole summary as one JSON line.")
    ] = False,
) -> None:
    """Evaluate a trained policy (deterministic) on the fixed evaluation TCs."""
    from distgprl.experiments.evaluation import describe, evaluate_run, summary_table
    from distgprl.methods import get_method

    preset = resolve_preset(preset, config)
    if repair_push and not plan_repair:
        raise UserInputError("--repair-push needs --plan-repair")
    if given_options(ctx, "policy") and not get_method(method).trainable:
        raise UserInputError(
            f"--policy: {method} is a reference, not trained: it has no final or best policy "
            "to choose (it is evaluated as it is); leave --policy out"
        )
    if plan_repair:
        from distgprl.experiments.safety_layer_evaluation import evaluate_with_repair
        from distgprl.safety_layer.retime import RepairConfig

        summary = evaluate_with_repair(
            task, method, seed, preset, episodes, root, policy, RepairConfig(repair=repair_push)
        )
    else:
        summary = evaluate_run(task, method, seed, preset, episodes, root, policy=policy)
    if as_json:
        typer.echo(describe(summary))
        return
    what = f"{task}/{method}/seed{seed} ({preset}, {policy} policy" + (
        ", safety layer in the loop)" if plan_repair else ")"
    )
    typer.echo(summary_table(summary, f"evaluation of {what}:"))
