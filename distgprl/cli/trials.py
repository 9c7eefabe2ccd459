"""`distgprl hardware`: trials of a trained DBM policy on a UR5e or its digital twin."""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Annotated

import typer

from distgprl.cli.common import (
    METHODS_HELP,
    ConfigOption,
    PresetOption,
    RootOption,
    given_options,
    resolve_preset,
    user_errors,
)
from distgprl.errors import UserInputError
from distgprl.trial_protocol import BEST_POLICY, TABLE2_POLICY, check_trial_policy


@user_errors
def hardware(
    ctx: typer.Context,
    trials: Annotated[int, typer.Option(min=1, help="Number of trials.")] = 10,
    method: Annotated[
        str,
        typer.Option(metavar="METHOD", help=f"Trained method whose policy adapts: {METHODS_HELP}."),
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
    protocol: Annotated[
        str,
        typer.Option(
            metavar="paper|safety-layer",
            help="paper: the policy's trajectory executes as made, only the UR5e's own joint "
            "speed/acceleration limits apply (a protective stop is a failed trial), as the "
            "paper ran Table II; safety-layer: this project's pre-flight check, retiming "
            "and repair before every motion (--force, --repair, --repair-push).",
        ),
    ] = "paper",
    force: Annotated[
        bool,
        typer.Option(help="Execute plans that fail the pre-flight check (safety-layer only)."),
    ] = False,
    preset: PresetOption = None,
    config: ConfigOption = None,
    model: Annotated[Path | None, typer.Option(help="Model file instead of the run's.")] = None,
    policy: Annotated[
        str,
        typer.Option(
            metavar="final|best",
            help="final: the run's model.zip, on disk where the run was trained (Table II "
            "counts its trials); best: the best policy the run ships, Table I's, in every "
            "clone (tabulated beside Table II, in table2_best).",
        ),
    ] = TABLE2_POLICY,
    root: RootOption = Path("results"),
    repair: Annotated[
        bool,
        typer.Option(
            help="Safety-layer protocol only: retime too-fast plans before refusing (with "
            "--repair-push also push too-close via-points; --no-repair: refuse at once)."
        ),
    ] = True,
    sensor_noise: Annotated[
        int,
        typer.Option(
            min=0,
            max=4,  # distgprl.hardware.twin.SENSOR_NOISE's levels (tested)
            help="Twin sensor noise: 0 none, 1 mild, 2 strong, 3-4 strong with a 2x / 4x "
            "worse calibration.",
        ),
    ] = 0,
    repair_push: Annotated[
        bool,
        typer.Option(
            help="Also push too-close via-points along the distance field (off by default: "
            "not yet shown to make a grazing plan safer, see RepairConfig)."
        ),
    ] = False,
) -> None:
    """Hardware trials on a UR5e (ur_rtde) or its digital twin; one CSV row per trial.

    The paper's protocol by default (`distgprl.trial_protocol`); an unknown
    ``--protocol`` is a user error (exit 2)."""
    from distgprl.experiments.trial_policy import load_trial_policy
    from distgprl.hardware.trial_rows import describe_summary
    from distgprl.hardware.trials import run_trials
    from distgprl.methods import get_method
    from distgprl.safety_layer.retime import RepairConfig
    from distgprl.trial_protocol import PAPER

    repairs = given_options(ctx, "repair", "repair_push")
    if protocol == PAPER and repairs:
        raise UserInputError(
            f"{' and '.join(repairs)}: the safety layer's repair: use --protocol safety-layer "
            "(the paper's protocol checks nothing before it moves), or leave them out"
        )
    backend = backend or ("ur" if robot_ip else "twin")
    ur_only = given_options(ctx, "robot_ip", "camera")
    if backend == "twin" and ur_only:
        raise UserInputError(
            f"{' and '.join(ur_only)}: the ur backend's (the twin simulates its robot and "
            "camera): use --backend ur, or leave them out"
        )
    if backend == "ur" and given_options(ctx, "sensor_noise"):
        raise UserInputError(
            "--sensor-noise sets the twin's simulated sensor noise; the ur backend's camera is "
            "a real one: leave it out (or use --backend twin)"
        )
    policy_options = given_options(ctx, "model", "policy")
    if policy_options and not get_method(method).trainable:
        raise UserInputError(
            f"{' and '.join(policy_options)}: {method} is a reference and runs no trained "
            "policy; leave them out (or give a trained --method)"
        )
    if model is not None and policy == BEST_POLICY:
        raise UserInputError(
            "--model runs the file it names; --policy best runs the best policy the run "
            "ships: give one of them"
        )
    if dry_run and judge == "operator":
        raise UserInputError(
            "--judge operator judges trials that moved; a --dry-run never moves, so there is "
            "nothing to judge: drop one of them"
        )
    preset = resolve_preset(preset, config)
    report = run_trials(
        trials=trials,
        method=method,
        seed=seed,
        backend=backend,
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
        protocol=protocol,
        load_policy=partial(load_trial_policy, policy=check_trial_policy(policy)),
    )
    typer.echo(f"{describe_summary(report.summary, protocol)} -> {report.path}")
