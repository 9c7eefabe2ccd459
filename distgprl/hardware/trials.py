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
   (:mod:`distgprl.hardware.repair`: re-timed if too fast, via-points pushed along the
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

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from distgprl.errors import UserInputError
from distgprl.hardware.controller import paper_protocol_meta
from distgprl.hardware.perception import (
    OBJECTS,
    CellCalibration,
    MarkerPerception,
    load_calibration,
    pose_error,
)
from distgprl.hardware.repair import RepairConfig
from distgprl.hardware.safety import (
    PlanCheck,
    SafetyLimits,
    UnsafePlanError,
    check_plan,
    ik_chain,
)
from distgprl.hardware.trial_policy import load_trial_policy
from distgprl.hardware.trial_rows import finish_row, judge_row, summarise_trials
from distgprl.hardware.window_check import (
    NO_VIA_POINTS,
    clearance_function,
    describe_repair,
    repair_window,
    safety_layer,
)
from distgprl.limits import UR5E_CONTROLLER, ControllerLimits
from distgprl.schema import TRIAL_FIELDS
from distgprl.trial_protocol import PAPER, PROTECTIVE_STOP, UNCHECKED, check_protocol


@dataclass(frozen=True)
class TrialReport:
    """Result of :func:`run_trials`: the rows, the CSV written and a summary."""

    rows: list[dict[str, Any]]
    path: Path
    summary: dict[str, float]


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
        dry_run: perceive, adapt and check every window without moving the robot.
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
            before refusing them (False: refuse at once, the behaviour before plan repair);
            the ``safety-layer`` protocol only (the paper's has no check to repair for).
        repair_config: settings of the repair (default :class:`RepairConfig`); its push
            (``repair=True``) does not apply to the residual ProMP methods, which have no
            via-points: the trial file's ``safety_layer`` says so and ``repair_push`` is
            False (`distgprl.hardware.window_check.safety_layer`).
        sensor_noise: twin sensor-noise level (:data:`~distgprl.hardware.twin.SENSOR_NOISE`:
            0 none, 1 mild, 2 strong); None keeps ``twin_config.noise`` (default none).
            Ignored by the ur backend (a real camera).
        protocol: ``paper`` (the default: the policy's poses execute as made, only the
            robot's own limits apply) or ``safety-layer`` (this project's pre-flight check
            and repair before every motion), `distgprl.trial_protocol`.
        controller: the twin's emulated controller limits (default the UR5e's documented
            ones; the real robot enforces its own).

    Returns:
        The rows, the CSV path and a summary (success/collision rates, MinCl).

    Raises:
        UserInputError: bad arguments, missing model, bad calibration, unreachable robot.
        KeyboardInterrupt: re-raised after stopping the robot and saving finished rows.
    """
    from distgprl.config import load_config
    from distgprl.hardware.adapter import perceived_env
    from distgprl.methods import get_method
    from distgprl.schema import write_csv

    if trials < 1:
        raise UserInputError("trials must be at least 1")
    if backend not in ("twin", "ur"):
        raise UserInputError(f"backend must be 'twin' or 'ur', got {backend!r}")
    if judge not in ("auto", "operator"):
        raise UserInputError(f"judge must be 'auto' or 'operator', got {judge!r}")
    get_method(method)  # an unknown name is a clear error before any hardware is touched
    check_protocol(protocol)
    paper = protocol == PAPER
    if paper and force:
        raise UserInputError(
            "force overrides the safety layer's pre-flight check: use it with the "
            "safety-layer protocol (the paper's protocol checks nothing before it moves)"
        )
    limits = limits or SafetyLimits()
    config = load_config(preset, task="dbm")
    rng = np.random.default_rng(seed)

    # -- calibration, backend -------------------------------------------------------------
    cal: CellCalibration
    robot: Any
    if backend == "twin":
        from distgprl.hardware.backends import TwinBackend
        from distgprl.hardware.twin import (
            TwinConfig,
            miscalibrated,
            sensor_noise_level,
            twin_calibration,
        )

        twin_config = twin_config or TwinConfig()
        if sensor_noise is not None:
            twin_config = replace(twin_config, noise=sensor_noise_level(sensor_noise))
        noise = twin_config.noise
        cal = load_calibration(calibration) if calibration else twin_calibration(twin_config)
        cal = miscalibrated(cal, noise, np.random.default_rng([seed, 4]))
    else:
        if calibration is None:
            raise UserInputError("the ur backend needs --calibration FILE (camera + markers)")
        cal = load_calibration(calibration)
        if camera is None:
            raise UserInputError("the ur backend needs --camera INDEX|URL")
    adapter = perceived_env(method, config.env, cal.conveyor_velocity)
    try:
        policy, provenance = load_trial_policy(method, seed, preset, root, model_path, adapter)
        if backend == "twin":
            robot = TwinBackend(
                twin_config,
                rng=np.random.default_rng([seed, 1]),
                noise_rng=np.random.default_rng([seed, 2]),
                controller=controller,
            )
        else:
            from distgprl.hardware.backends import OpenCVCamera, URBackend

            robot = URBackend(robot_ip or "", limits, rtde_factory=rtde_factory)
            if hasattr(camera, "capture"):
                robot.camera = camera
            else:
                assert camera is not None  # the ur backend checked it above
                robot.camera = OpenCVCamera(camera, robot.now, (cal.width, cal.height))
    except BaseException:
        adapter.close()
        raise
    perception: MarkerPerception
    if backend == "twin" and twin_config.noise.corner_noise_px > 0:
        from distgprl.hardware.twin import NoisyCornerPerception

        perception = NoisyCornerPerception(
            cal, twin_config.noise.corner_noise_px, np.random.default_rng([seed, 3])
        )
    else:
        perception = MarkerPerception(cal)
    repair = repair and not paper  # the paper's protocol has no check to repair for
    handling = (repair_config or RepairConfig()) if repair else None
    layer = (
        {"checked_unit": str(adapter.decision_unit), **paper_protocol_meta(controller)}
        if paper
        else safety_layer(adapter, handling, force)
    )
    if layer.get("push") == NO_VIA_POINTS:  # the push was asked for and does not apply
        echo(f"{method}: --repair-push {layer['push']}; retiming only")
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    folder = Path(root) / "hardware" / ("dry-run" if dry_run else "") / method
    prefix = "plans" if dry_run else "trials"
    path = folder / f"{prefix}_{backend}_seed{seed}_{stamp}.csv"
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
    rows: list[dict[str, Any]] = []
    dt = adapter.control_dt
    tcs = [adapter.spec_task.sample_tc(rng) for _ in range(trials)]

    def save() -> None:
        if rows:
            write_csv(path, rows, TRIAL_FIELDS, **meta)

    try:
        for index in range(trials):
            row = _one_trial(
                index,
                tcs[index],
                robot,
                perception,
                adapter,
                policy,
                limits,
                dt,
                dry_run,
                judge,
                force,
                ask,
                echo,
                handling,
                paper,
            )
            row["backend"] = backend
            rows.append(row)
            save()
            echo(
                f"trial {index + 1}/{trials}: {row['status']} success={row['success']} "
                f"collision={row['collision']} min_clearance={row['min_clearance']}"
            )
    except KeyboardInterrupt:
        robot.stop()
        echo(f"interrupted: robot stopped; {len(rows)} finished trial(s) saved to {path}")
        save()
        raise
    finally:
        robot.close()
        adapter.close()
    return TrialReport(rows, path, summarise_trials(rows))


def _one_trial(
    index,
    tc,
    robot,
    perception,
    adapter,
    policy,
    limits,
    dt,
    dry_run,
    judge,
    force,
    ask,
    echo,
    repair_config: RepairConfig | None = None,
    paper: bool = False,
) -> dict[str, Any]:
    trial_start = time.perf_counter()
    twin = robot.name == "twin"
    row: dict[str, Any] = dict.fromkeys(TRIAL_FIELDS, "")
    row.update(trial=index, status="ok", images=0)
    # seconds, but "perception": the detections' times (ms) (`trial_rows.finish_row`)
    timings: dict[str, Any] = {"perception": [], "policy": 0.0, "check": 0.0, "execution": 0.0}
    errors: list[tuple[float, float]] = []
    planned = np.inf

    perception.reset_tracks()
    adapter.world.tracks.clear()
    if twin:
        robot.start_trial(tc)
        row["true_object_offset_y"] = tc.object_offset[1]
        row["true_obstacle_offset_y"] = tc.obstacle_offset[1]
    elif not dry_run:  # a dry run plans from wherever the robot is and never moves it
        ask(f"trial {index + 1}: place both bars on the conveyor, then press Enter ")
        q_home = adapter.model.start_joint_positions
        path = np.linspace(robot.joint_positions(), q_home, 50)
        poses = np.array([_fk_pose(adapter.model.robot, q) for q in path])
        check_plan(poses, path[0], adapter.model.robot, limits, dt * 4, force=force)
        result = robot.move_joints(q_home)
        if result.stopped:
            row.update(status="stopped", stop_reason=result.stop_reason)
            return finish_row(row, trial_start, timings, errors, planned, judge_skip=True)

    def perceive() -> bool:
        image, stamp = robot.capture()
        percept = perception.perceive(image, stamp)
        timings["perception"].append(percept.detection_ms)
        row["images"] += 1
        adapter.world.update(percept)
        adapter.world.set_robot(robot.tcp_pose(), robot.now(), robot.joint_positions())
        if twin:
            truth = robot.sim.object_transforms()
            # the image was taken at `stamp`; compare with the truth predicted back to it
            for name, pose in percept.objects.items():
                true = truth[name].copy()
                if adapter.world.on_belt(true):
                    true[:3, 3] -= adapter.world.velocity * (robot.now() - stamp)
                errors.append(pose_error(pose.transform, true))
        return all(name in adapter.world.tracks for name in OBJECTS)

    if not perceive():
        row.update(status="not_perceived", stop_reason="a bar was not detected at the start")
        return finish_row(row, trial_start, timings, errors, planned, judge_skip=True)
    now = robot.now()
    perceived_tc = adapter.begin(robot.tcp_pose(), now)
    row["object_offset_y"] = round(perceived_tc.object_offset[1], 5)
    row["obstacle_offset_y"] = round(perceived_tc.obstacle_offset[1], 5)
    q = robot.joint_positions()
    velocity = np.zeros(6)
    clock = now  # predicted time in dry-run (nothing moves)
    shift = np.zeros(3)  # belt shift of re-timed plans (repair module docstring)
    last_pose = None  # last commanded pose (with the shift)
    windows: list[tuple[str, float, float]] = []  # (decision, time added s, displacement m)
    streaming = False  # the robot's stream left open for the next RL step
    unit = adapter.decision_unit  # a window, or one 0.1 s RL step (residual RL)
    for step in range(adapter.trial_steps):
        if step > 0 and not dry_run and adapter.takes_image(step):
            perceive()
        elif step > 0 and not dry_run:  # no image: the tracks predict the bars; the robot's
            adapter.world.set_robot(robot.tcp_pose(), robot.now(), robot.joint_positions())
        elif step > 0:
            adapter.world.set_robot(
                adapter.last_commanded if last_pose is None else last_pose, clock, q
            )
        start = time.perf_counter()
        observation = adapter.observe()
        action = None if policy is None else policy(observation)
        timings["policy"] += time.perf_counter() - start
        poses = adapter.adapt(action)
        reference = clock if dry_run else robot.now()
        clearance_at = clearance_function(
            adapter.field, adapter.world.obstacle_shapes, reference, dt
        )
        path_poses = poses
        if paper:  # the paper's protocol: the poses go as made; the controller alone stops
            check = PlanCheck(ik_chain(poses, q, adapter.model.robot)[0], np.inf)
            windows.append((UNCHECKED, 0.0, 0.0))
        elif repair_config is None:
            try:
                check = check_plan(
                    poses,
                    q,
                    adapter.model.robot,
                    limits,
                    dt,
                    clearance_at,
                    force=force,
                    v_start=velocity,
                )
            except UnsafePlanError as refused:
                echo(f"trial {index + 1}, {unit} {step + 1}: {refused}")
                windows.append(("refused", 0.0, 0.0))
                row.update(
                    status="refused",
                    refused_limits=",".join(dict.fromkeys(v.limit for v in refused.violations)),
                    stop_reason=str(refused),
                )
                break
            windows.append(("refused" if check.violations else "none", 0.0, 0.0))
            timings["check"] += check.check_ms / 1000.0
        else:
            started = time.perf_counter()
            repaired = repair_window(
                adapter,
                step,
                poses,
                q,
                velocity,
                limits,
                dt,
                clearance_at,
                reference,
                shift,
                repair_config,
            )
            timings["check"] += time.perf_counter() - started
            windows.append((repaired.decision, repaired.time_added, repaired.max_displacement))
            if repaired.decision != "none" or dry_run:
                echo(f"trial {index + 1}, {unit} {step + 1}: {describe_repair(repaired)}")
            if repaired.decision == "refused" and not force:
                refusal = UnsafePlanError(repaired.remaining)
                row.update(
                    status="refused",
                    refused_limits=",".join(repaired.refused_limits),
                    stop_reason=f"after retiming and repair: {refusal}",
                )
                break
            check, poses, path_poses = repaired.check, repaired.poses, repaired.path_poses
            shift = repaired.shift_end
            if repaired.decision == "refused":  # forced: executed as given, recorded
                row["refused_limits"] = ",".join(repaired.refused_limits)
        planned = min(planned, check.min_clearance)
        if check.violations and repair_config is None:
            row["refused_limits"] = ",".join(dict.fromkeys(v.limit for v in check.violations))
        if dry_run:
            adapter.executed(path_poses)
            if len(poses):
                last_pose = np.asarray(poses[-1], dtype=float).copy()
            clock += len(poses) * dt
            if len(check.joints):
                velocity = (check.joints[-1] - (check.joints[-2] if len(poses) > 1 else q)) / dt
                q = check.joints[-1]
            continue
        # residual control streams its RL steps back to back (the robot's stream is not
        # ended between them); a window plan ends its stream
        last = not adapter.streams_decisions or step == adapter.trial_steps - 1
        result = robot.execute(check.joints, poses, last=last)
        streaming = not last and not result.stopped
        timings["execution"] += result.wall_s
        adapter.executed(path_poses[: result.steps])
        if result.steps:
            last_pose = np.asarray(poses[result.steps - 1], dtype=float).copy()
            previous = check.joints[result.steps - 2] if result.steps > 1 else q
            q = check.joints[result.steps - 1]
            velocity = (q - previous) / dt
        if result.stopped:  # a controller's limit stop is a failure, not a refusal
            status = PROTECTIVE_STOP if result.limit_stop else "stopped"
            row.update(status=status, stop_reason=result.stop_reason)
            if result.protective_stop and result.collision is not False:
                row["collision"] = 1  # a contact (the real robot: any protective stop)
            break
        if not twin and not streaming:  # a continued stream goes on from its last target
            q = robot.joint_positions()
    if streaming:  # a refusal ended the trial with the robot's stream still open
        robot.stop()
    row["repair"] = ";".join(w[0] for w in windows)
    row["repair_added_s"] = ";".join(f"{w[1]:.3f}" for w in windows)
    row["repair_displacement_m"] = ";".join(f"{w[2]:.4f}" for w in windows)

    # -- judge ---------------------------------------------------------------------------
    if dry_run:
        if row["status"] == "ok":
            row["status"] = "planned"
        return finish_row(row, trial_start, timings, errors, planned)
    judge_row(row, robot, adapter, twin=twin, judge=judge, ask=ask, index=index, perceive=perceive)
    return finish_row(row, trial_start, timings, errors, planned)


def _fk_pose(robot, q: np.ndarray) -> np.ndarray:
    from distgprl.sim.transforms import matrix_to_pose

    return matrix_to_pose(robot.fk(q))
