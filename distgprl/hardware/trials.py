"""Hardware trials (paper §V-A, Table II): perceive, condition, adapt online, execute, judge.

One trial on the DBM cell:

1. the cell is set up (twin: a TC drawn from the trial generator; real robot: the operator
   places the bars and the robot goes to the start configuration);
2. an image is taken; ArUco perception gives the bars in the robot base frame; the skill is
   conditioned on the perceived target bar (its pose predicted along the belt to now);
3. for each of the 3 windows (residual RL, ProMP-RRL: each of the 50 RL steps of 0.1 s,
   with a fresh image at the first step of each window's span and the tracks' prediction
   along the belt in between): a fresh image updates the bar tracks and the distance field
   (static cell geometry + perceived other bar), the trained policy adapts the window (sets
   the step's residual) from the observation built exactly as in training, and the
   segment's poses go to the robot — under the paper's protocol (``protocol="paper"``, the
   default, `distgprl.trial_protocol`) as they are, the robot's controller alone
   enforcing its own limits (a command beyond them ends the trial in a protective stop);
   under the ``safety-layer`` protocol after the plan repair
   (:mod:`distgprl.safety_layer.repair`: re-timed if too fast, via-points pushed along the
   distance field's gradient if too close — a residual step has none to push) and the
   safety layer's pre-flight check (refused if still unsafe, unless ``force``);
4. the trial is judged (twin: from the simulation; real robot: operator prompt, or the
   perceived lift and the controller's protective stops with ``judge="auto"``).

Residual control's RL steps are streamed back to back: the robot's stream is ended (a
deceleration to standstill) only after the trial's last step or a refusal, not between steps.

A row per trial is written (atomically, after every trial) to
``<root>/hardware/<method>/trials_<backend>_seed<k>_<UTC>.csv``; its meta says which
protocol the trials ran under (``protocol``: ``paper`` or ``safety-layer``), what one
decision covers (``checked_unit``: ``window`` or ``RL step``) and what ran before each
decision moved (``safety_layer``: the check, retiming, the push or why it does not apply;
under the paper's protocol none of them, and the controller's limits); ``dry_run``
writes plans to ``<root>/hardware/dry-run/<method>/`` instead (not read by the tables) and
never moves.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from distgprl.errors import UserInputError
from distgprl.hardware.controller import paper_protocol_meta
from distgprl.hardware.perception import (
    CellCalibration,
    MarkerPerception,
    load_calibration,
)
from distgprl.hardware.trial_episode import TrialSetup, one_trial
from distgprl.hardware.trial_rows import describe_trial, summarise_trials
from distgprl.limits import UR5E_CONTROLLER, ControllerLimits, SafetyLimits
from distgprl.safety_layer.retime import RepairConfig
from distgprl.safety_layer.window_check import NO_VIA_POINTS, safety_layer
from distgprl.schema import TRIAL_FIELDS
from distgprl.trial_protocol import PAPER, check_protocol


@dataclass(frozen=True)
class TrialReport:
    """Result of :func:`run_trials`: the rows, the CSV written and a summary."""

    rows: list[dict[str, Any]]
    path: Path
    summary: dict[str, float]


class PolicyLoader(Protocol):
    """Loads the policy a trial runs: ``(method, seed, preset, root, model_path, env) ->
    (policy or None, provenance)``, the policy mapping an observation to an action (None for
    a reference method), ``env`` the trial's environment (`TrialAdapter.env`); the CLI and
    the sweep's twin trials pass `distgprl.experiments.trial_policy.load_trial_policy`."""

    def __call__(
        self,
        method: str,
        seed: int,
        preset: str,
        root: str | Path,
        model_path: str | Path | None,
        env: Any,
    ) -> tuple[Callable[[Any], np.ndarray] | None, dict[str, Any]]: ...


def run_trials(
    trials: int = 10,
    method: str = "dist-gprl",
    seed: int = 0,
    backend: str = "twin",
    robot_ip: str | None = None,
    camera: str | Any | None = None,
    calibration: str | Path | None = None,
    dry_run: bool = False,
    judge: str = "auto",
    force: bool = False,
    root: str | Path = "results",
    preset: str = "paper",
    model_path: str | Path | None = None,
    twin_config=None,
    limits: SafetyLimits | None = None,
    ask: Callable[[str], str] = input,
    echo: Callable[[str], None] = print,
    rtde_factory: Callable | None = None,
    repair: bool = True,
    repair_config: RepairConfig | None = None,
    sensor_noise: int | None = None,
    protocol: str = PAPER,
    controller: ControllerLimits = UR5E_CONTROLLER,
    load_policy: PolicyLoader | None = None,
) -> TrialReport:
    """Run hardware trials of a trained DBM policy (see the module docstring).

    Args:
        trials: number of trials (>= 1).
        method: a trained method (``dist-gprl``, ``gprl-d``, ..., ``promp-rrl``) or a
            reference: ``demo`` (the unadapted conditioned demonstration), ``promp-nominal``
            (ProMP-RRL's nominal, zero residual).
        seed: training seed of the policy; also seeds the twin's TCs and sensor noise.
        backend: ``twin`` (digital twin) or ``ur`` (UR5e via ur_rtde).
        robot_ip: controller address (``ur``).
        camera: camera device index or URL (``ur``), or an object with
            ``capture() -> (image, stamp)`` on the robot backend's clock.
        calibration: calibration file (YAML/JSON); the twin defaults to its exact one.
        dry_run: perceive and adapt every decision (and, under the ``safety-layer``
            protocol, check it) without moving the robot.
        judge: ``auto`` (twin: simulation; ur: perceived lift + protective stops) or
            ``operator`` (ask success/collision after each trial).
        force: execute plans that violate a safety limit (violations still recorded);
            the ``safety-layer`` protocol only.
        root: results root; preset: the policy's training preset.
        model_path: policy zip (default ``<root>/<preset>/dbm/<method>/seed<k>/model.zip``).
        twin_config: :class:`~distgprl.hardware.twin.TwinConfig` (camera, noise, latency).
        limits: safety limits (default :class:`SafetyLimits`).
        ask: prompt function (operator judge, bar placement); echo: progress output.
        rtde_factory: ``ip -> (control, receive)`` for the ur backend (tests inject a fake).
        repair: retime / repair unsafe window plans (residual control: 0.1 s RL steps)
            before refusing them (False: refuse at once);
            the ``safety-layer`` protocol only (the paper's has no check to repair for).
        repair_config: settings of the repair (default :class:`RepairConfig`); its push
            (``repair=True``) does not apply to the residual ProMP methods, which have no
            via-points: the trial file's ``safety_layer`` says so and ``repair_push`` is
            False (`distgprl.safety_layer.window_check.safety_layer`).
        sensor_noise: twin sensor-noise level (:data:`~distgprl.hardware.twin.SENSOR_NOISE`:
            0 none, 1 mild, 2 strong, 3 and 4 level 2's camera with a two and four times
            worse calibration); None keeps ``twin_config.noise`` (default none).
            Ignored by the ur backend (a real camera).
        protocol: ``paper`` (the default: the policy's poses execute as made, only the
            robot's own limits apply) or ``safety-layer`` (this project's pre-flight check
            and repair before every motion), `distgprl.trial_protocol`.
        controller: the twin's emulated controller limits (default the UR5e's documented
            ones; the real robot enforces its own).
        load_policy: loads the trained policy (`PolicyLoader`); required for a trained
            method, None runs a reference method (``demo``, ``promp-nominal``).

    Returns:
        The rows, the CSV path and a summary (success/collision rates, MinCl).

    Raises:
        UserInputError: bad arguments, missing model, bad calibration, unreachable robot.
        KeyboardInterrupt: re-raised after stopping the robot and saving finished rows.
    """
    from distgprl.config import load_config
    from distgprl.hardware.adapter import perceived_env

    _check_arguments(trials, method, backend, judge, force, protocol)
    paper = protocol == PAPER
    limits = limits or SafetyLimits()
    config = load_config(preset, task="dbm")
    rng = np.random.default_rng(seed)
    if backend == "twin":
        twin_config = _twin_config(twin_config, sensor_noise)
    cal = _cell_calibration(backend, calibration, camera, twin_config, seed)
    adapter = perceived_env(method, config.env, cal.conveyor_velocity)
    try:
        policy, provenance = _trial_policy(
            load_policy, method, seed, preset, root, model_path, adapter
        )
        robot = _connect_robot(
            backend, twin_config, seed, controller, robot_ip, limits, rtde_factory, camera, cal
        )
    except BaseException:
        adapter.close()
        raise
    perception = _perception(backend, twin_config, cal, seed)
    repair = repair and not paper  # the paper's protocol has no check to repair for
    handling = (repair_config or RepairConfig()) if repair else None
    layer = (
        {"checked_unit": str(adapter.decision_unit), **paper_protocol_meta(controller)}
        if paper
        else safety_layer(adapter.env, adapter.decision_unit, handling, force)
    )
    if layer.get("push") == NO_VIA_POINTS:  # the push was asked for and does not apply
        echo(f"{method}: --repair-push {layer['push']}; retiming only")
    path = _trial_file(root, method, backend, seed, dry_run)
    meta = {
        "kind": "hardware-trials",
        "protocol": protocol,  # the paper's (no pre-flight check) or the safety layer's
        "method": method,
        "seed": seed,
        "backend": backend,
        "preset": preset,
        "dry_run": dry_run,
        "judge": judge,
        "force": force,
        "repair": repair,
        # whether via-points were pushed: asked for and the method has via-points to push
        "repair_push": layer.get("push") == "on",
        "sensor_noise": sensor_noise if backend == "twin" else None,
        "twin_noise": asdict(twin_config.noise) if backend == "twin" else None,
        "limits": {k: v for k, v in limits.__dict__.items()},
        "policy": provenance,  # which trained model ran (empty for the unadapted demo)
        # what the safety layer checks before it moves: a window's plan, or one RL step's
        "checked_unit": adapter.decision_unit,
        # what ran before each decision moved: the safety layer's check, retiming, the push
        # (or why it does not apply); under the paper's protocol none, the controller's limits
        "safety_layer": layer,
    }
    setup = TrialSetup(
        robot,
        perception,
        adapter,
        policy,
        limits,
        dry_run,
        judge,
        force,
        ask,
        echo,
        handling,
        paper,
    )
    tcs = [adapter.env.spec_task.sample_tc(rng) for _ in range(trials)]
    rows = _run_all(setup, tcs, backend, path, meta)
    return TrialReport(rows, path, summarise_trials(rows))


def _trial_policy(
    load_policy: PolicyLoader | None, method, seed, preset, root, model_path, adapter
):
    """(policy or None, provenance) from ``load_policy``; a reference method needs none."""
    if load_policy is not None:
        return load_policy(method, seed, preset, root, model_path, adapter.env)
    if adapter.env.method.trainable:
        raise UserInputError(
            f"{method}: a trained method's trials need a policy loader (load_policy, e.g. "
            "distgprl.experiments.trial_policy.load_trial_policy)"
        )
    return None, {}


def _check_arguments(
    trials: int, method: str, backend: str, judge: str, force: bool, protocol: str
) -> None:
    """A clear error for a bad argument, before any hardware is touched."""
    from distgprl.methods import get_method

    if trials < 1:
        raise UserInputError("trials must be at least 1")
    if backend not in ("twin", "ur"):
        raise UserInputError(f"backend must be 'twin' or 'ur', got {backend!r}")
    if judge not in ("auto", "operator"):
        raise UserInputError(f"judge must be 'auto' or 'operator', got {judge!r}")
    get_method(method)  # an unknown name is a clear error
    check_protocol(protocol)
    if protocol == PAPER and force:
        raise UserInputError(
            "force overrides the safety layer's pre-flight check: use it with the "
            "safety-layer protocol (the paper's protocol checks nothing before it moves)"
        )


def _twin_config(twin_config, sensor_noise: int | None):
    """The twin's settings, at ``sensor_noise``'s level where it is given."""
    from distgprl.hardware.twin import TwinConfig, sensor_noise_level

    twin_config = twin_config or TwinConfig()
    if sensor_noise is not None:
        twin_config = replace(twin_config, noise=sensor_noise_level(sensor_noise))
    return twin_config


def _cell_calibration(backend: str, calibration, camera, twin_config, seed: int) -> CellCalibration:
    """The cell's calibration: the file given, else the twin's own (miscalibrated by its
    noise); the ur backend needs a file and a camera."""
    if backend == "twin":
        from distgprl.hardware.twin import miscalibrated, twin_calibration

        noise = twin_config.noise
        cal = load_calibration(calibration) if calibration else twin_calibration(twin_config)
        return miscalibrated(cal, noise, np.random.default_rng([seed, 4]))
    if calibration is None:
        raise UserInputError("the ur backend needs --calibration FILE (camera + markers)")
    cal = load_calibration(calibration)
    if camera is None:
        raise UserInputError("the ur backend needs --camera INDEX|URL")
    return cal


def _connect_robot(
    backend, twin_config, seed, controller, robot_ip, limits, rtde_factory, camera, cal
) -> Any:
    """The robot backend: the twin (seeded) or the UR5e with its camera."""
    if backend == "twin":
        from distgprl.hardware.backends import TwinBackend

        return TwinBackend(
            twin_config,
            rng=np.random.default_rng([seed, 1]),
            noise_rng=np.random.default_rng([seed, 2]),
            controller=controller,
        )
    from distgprl.hardware.backends import OpenCVCamera, URBackend

    robot = URBackend(robot_ip or "", limits, rtde_factory=rtde_factory)
    if hasattr(camera, "capture"):
        robot.camera = camera
    else:
        assert camera is not None  # the ur backend checked it above
        robot.camera = OpenCVCamera(camera, robot.now, (cal.width, cal.height))
    return robot


def _perception(backend: str, twin_config, cal: CellCalibration, seed: int) -> MarkerPerception:
    """ArUco perception; the twin's with pixel noise on the corners where it has some."""
    if backend == "twin" and twin_config.noise.corner_noise_px > 0:
        from distgprl.hardware.twin import NoisyCornerPerception

        return NoisyCornerPerception(
            cal, twin_config.noise.corner_noise_px, np.random.default_rng([seed, 3])
        )
    return MarkerPerception(cal)


def _trial_file(root, method: str, backend: str, seed: int, dry_run: bool) -> Path:
    """Where the trials' rows go (the module docstring)."""
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    folder = Path(root) / "hardware" / ("dry-run" if dry_run else "") / method
    prefix = "plans" if dry_run else "trials"
    return folder / f"{prefix}_{backend}_seed{seed}_{stamp}.csv"


def _run_all(setup: TrialSetup, tcs: list, backend: str, path: Path, meta: dict) -> list:
    """Run a trial per TC, writing the rows after each; on an interrupt stop the robot and
    save what finished. The robot and the adapter are closed at the end."""
    from distgprl.schema import write_csv

    robot, echo = setup.robot, setup.echo
    rows: list[dict[str, Any]] = []

    def save() -> None:
        if rows:
            write_csv(path, rows, TRIAL_FIELDS, **meta)

    try:
        for index, tc in enumerate(tcs):
            row = one_trial(setup, index, tc)
            row["backend"] = backend
            rows.append(row)
            save()
            echo(f"trial {index + 1}/{len(tcs)}: {describe_trial(row)}")
    except KeyboardInterrupt:
        robot.stop()
        echo(f"interrupted: robot stopped; {len(rows)} finished trial(s) saved to {path}")
        save()
        raise
    finally:
        robot.close()
        setup.adapter.close()
    return rows
